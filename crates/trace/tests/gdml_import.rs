//! The GDML reader and scene builder on small files written here: units and Geant4's
//! half-length rules against values worked out by hand, placement conventions, loops,
//! instancing, errors naming file, line and element, and a fuzz test of mutated files.
//! (The 50 shared public files are checked against Geant4 itself in
//! `tests/tests/gdml_oracle.rs`.)

use std::f64::consts::PI;
use std::path::Path;
use std::process::Command;

use hytrace_foundry::g4solid::G4Solid;
use hytrace_foundry::gdml::{parse_gdml, read_gdml, Gdml, GdmlOptions};
use hytrace_testkit::{Random, XorShift64Star};
use hytrace_trace::scene::{gdml_to_foundry, load_gdml_scene};

fn gdml(defines: &str, solids: &str, structure: &str) -> String {
    format!(
        r#"<?xml version="1.0" encoding="UTF-8"?>
<gdml>
<define>
{defines}
</define>
<materials>
  <material name="Air" Z="7"><D value="0.0012"/><atom value="14"/></material>
  <material name="Glass" Z="14"><D value="2.2"/><atom value="28"/></material>
</materials>
<solids>
  <box name="WorldBox" x="10" y="10" z="10" lunit="m"/>
{solids}
</solids>
<structure>
{structure}
</structure>
<setup name="Default" version="1.0"><world ref="World"/></setup>
</gdml>
"#
    )
}

/// A world volume holding the given physvols.
fn world(physvols: &str) -> String {
    format!(
        r#"<volume name="World"><materialref ref="Air"/><solidref ref="WorldBox"/>
{physvols}
</volume>"#
    )
}

fn read(text: &str) -> Gdml {
    parse_gdml(text, "test.gdml", &GdmlOptions::default()).unwrap_or_else(|e| panic!("{e}"))
}

fn solid<'a>(g: &'a Gdml, name: &str) -> &'a G4Solid {
    &g.solids.iter().find(|s| s.name == name).unwrap().solid
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-12 * (1.0 + a.abs().max(b.abs()))
}

#[test]
fn units_and_half_lengths_follow_geant4() {
    let g = read(&gdml(
        r#"<constant name="L" value="2*cm"/>
           <quantity name="R" value="3" unit="cm"/>
           <variable name="v" value="1"/>
           <expression name="E">2*(HALFPI+0.2*PI)</expression>
           <matrix name="m" coldim="2" values="1 2 3 4"/>"#,
        r#"<box name="b" x="L" y="4" z="6" lunit="mm"/>
           <box name="bcm" x="2" y="4" z="6" lunit="cm"/>
           <tube name="t" rmin="1" rmax="R" z="10" startphi="0" deltaphi="E" aunit="rad"/>
           <cone name="c" rmin1="0" rmax1="2" rmin2="0" rmax2="1" z="8" deltaphi="360" aunit="deg"/>
           <eltube name="e" dx="1" dy="2" dz="3"/>
           <paraboloid name="p" rlo="1" rhi="2" dz="5"/>
           <polycone name="pc" startphi="0" deltaphi="90" aunit="deg">
             <zplane z="-7" rmin="0" rmax="1"/><zplane z="11" rmin="0" rmax="m[2,1]"/>
           </polycone>
           <trd name="trd" x1="2" x2="4" y1="6" y2="8" z="10"/>
           <hype name="h" rmin="1" rmax="2" inst="0" outst="0.5" z="12"/>"#,
        &world(""),
    ));
    assert_eq!(
        solid(&g, "b"),
        &G4Solid::Box {
            dx: 10.0,
            dy: 2.0,
            dz: 3.0
        }
    );
    assert_eq!(
        solid(&g, "bcm"),
        &G4Solid::Box {
            dx: 10.0,
            dy: 20.0,
            dz: 30.0
        }
    );
    let G4Solid::Tubs {
        rmin,
        rmax,
        dz,
        sphi,
        dphi,
    } = *solid(&g, "t")
    else {
        panic!()
    };
    assert_eq!((rmin, rmax, dz, sphi), (1.0, 30.0, 5.0, 0.0));
    assert!(close(dphi, 2.0 * (PI / 2.0 + 0.2 * PI)));
    let G4Solid::Cons { dz, dphi, .. } = *solid(&g, "c") else {
        panic!()
    };
    assert!(dz == 4.0 && close(dphi, 2.0 * PI));
    assert_eq!(
        solid(&g, "e"),
        &G4Solid::Eltube {
            dx: 1.0,
            dy: 2.0,
            dz: 3.0
        }
    );
    assert_eq!(
        solid(&g, "p"),
        &G4Solid::Paraboloid {
            dz: 5.0,
            rlo: 1.0,
            rhi: 2.0
        }
    );
    let G4Solid::Polycone { z, rmax, dphi, .. } = solid(&g, "pc") else {
        panic!()
    };
    // Absolute z planes; m[2,1] is the first element of the second row (1-based).
    assert_eq!(
        (z.clone(), rmax.clone()),
        (vec![-7.0, 11.0], vec![1.0, 3.0])
    );
    assert!(close(*dphi, PI / 2.0));
    assert_eq!(
        solid(&g, "trd"),
        &G4Solid::Trd {
            dx1: 1.0,
            dx2: 2.0,
            dy1: 3.0,
            dy2: 4.0,
            dz: 5.0
        }
    );
    let G4Solid::Hype { dz, stereo_out, .. } = *solid(&g, "h") else {
        panic!()
    };
    assert!(dz == 6.0 && stereo_out == 0.5);
    // The world box in metres.
    assert_eq!(
        solid(&g, "WorldBox"),
        &G4Solid::Box {
            dx: 5000.0,
            dy: 5000.0,
            dz: 5000.0
        }
    );
}

#[test]
fn physvol_rotation_places_the_daughter_by_the_inverse_and_booleans_directly() {
    let g = read(&gdml(
        r#"<rotation name="rx" x="90" unit="deg"/>"#,
        r#"<box name="small" x="2" y="2" z="2"/>
           <box name="a" x="100" y="10" z="10"/>
           <union name="u"><first ref="a"/><second ref="a"/>
             <position name="up" x="0" y="0" z="0"/>
             <rotation name="rz" z="90" unit="deg"/></union>"#,
        &format!(
            r#"<volume name="S"><materialref ref="Glass"/><solidref ref="small"/></volume>
               {}"#,
            world(
                r#"<physvol name="s1"><volumeref ref="S"/><position name="p" x="1" y="2" z="3"/><rotationref ref="rx"/></physvol>"#
            )
        ),
    ));
    let p = &g.volumes[g.world].daughters[0];
    // Rx(90) maps +y to +z; Geant4 places the daughter by its inverse: +y goes to -z.
    let q = p.transform.apply_point([0.0, 1.0, 0.0]);
    assert!(
        close(q[0], 1.0) && close(q[1], 2.0) && close(q[2], 3.0 - 1.0),
        "{q:?}"
    );
    // A boolean's rotation applies directly: +x of the second box turns to +y.
    let G4Solid::Union(b) = solid(&g, "u") else {
        panic!()
    };
    let r = b.rotation;
    assert!(close(r[1][0], 1.0) && close(r[0][1], -1.0), "{r:?}");
}

#[test]
fn loops_generate_names_and_placements_and_repeated_volumes_share_one_solid() {
    let text = gdml(
        r#"<variable name="i" value="0"/><constant name="n" value="400"/>"#,
        r#"<loop for="i" from="1" to="3" step="1"><box name="B[i]" x="i" y="1" z="1"/></loop>
           <box name="pmt" x="5" y="5" z="5"/>"#,
        &format!(
            r#"<volume name="P"><materialref ref="Glass"/><solidref ref="pmt"/></volume>
               {}"#,
            world(
                r#"<loop for="i" from="0" to="n-1" step="1">
                     <physvol copynumber="i"><volumeref ref="P"/>
                       <position name="pos" x="10*fmod(i,20)" y="10*floor(i/20)" z="0"/></physvol>
                   </loop>"#
            )
        ),
    );
    let g = read(&text);
    // Geant4's SolveBrackets: 1-based indices in brackets become 0-based name suffixes.
    for (k, name) in ["B_0", "B_1", "B_2"].iter().enumerate() {
        assert_eq!(
            solid(&g, name),
            &G4Solid::Box {
                dx: (k + 1) as f64 / 2.0,
                dy: 0.5,
                dz: 0.5
            }
        );
    }
    let f = gdml_to_foundry(&g).unwrap();
    assert_eq!(f.inst.len(), 401);
    assert_eq!(f.solid.len(), 2, "the world and one shared solid");
    let copies: Vec<i32> = f.inst[1..].iter().map(|i| i.copy_number).collect();
    let mut sorted = copies.clone();
    sorted.sort();
    assert_eq!(sorted, (0..400).collect::<Vec<_>>());
    // Every sensor's boundary: Air outside, Glass inside.
    let b = f.optics.boundaries[f.inst[1].boundary as usize];
    assert_eq!(f.optics.materials[b.outer_material as usize].name, "Air");
    assert_eq!(f.optics.materials[b.inner_material as usize].name, "Glass");
}

/// Writes `text` to a file and expects loading it to fail with all of `needles` in the
/// message (which must name the file).
fn expect_error(text: &str, needles: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.gdml");
    std::fs::write(&path, text).unwrap();
    let e = format!(
        "{:#}",
        load_gdml_scene(&path, &GdmlOptions::default()).expect_err("must fail")
    );
    assert!(e.contains("bad.gdml"), "no file name in: {e}");
    for n in needles {
        assert!(e.contains(n), "`{n}` not in: {e}");
    }
}

#[test]
fn bad_files_give_errors_with_file_line_and_element() {
    expect_error(
        "<gdml><solids><box name='a' x='1'</solids></gdml>",
        &["malformed XML", ":1:"],
    );
    expect_error(
        &gdml(
            "",
            "",
            r#"<volume name="World"><materialref ref="Air"/><solidref ref="nope"/></volume>"#,
        ),
        &[
            "unknown solid `nope`",
            "gdml/structure/volume[name=World]/solidref",
            ":15:",
        ],
    );
    expect_error(
        &gdml("", r#"<blob name="x"/>"#, &world("")),
        &["unsupported solid <blob>", "gdml/solids/blob[name=x]"],
    );
    expect_error(
        &gdml("", r#"<box name="b" x="2*(3+" y="1" z="1"/>"#, &world("")),
        &["attribute `x`", "cannot evaluate", "box[name=b]"],
    );
    expect_error(
        &gdml(
            "",
            r#"<box name="b" x="undefined_thing" y="1" z="1"/>"#,
            &world(""),
        ),
        &["unknown name \"undefined_thing\""],
    );
    // An impossible solid is found when it is built; the error points at its definition.
    expect_error(
        &gdml(
            "",
            r#"<tube name="neg" rmin="0" rmax="-5" z="10" deltaphi="6.3"/>"#,
            &format!(
                r#"<volume name="N"><materialref ref="Air"/><solidref ref="neg"/></volume>{}"#,
                world(r#"<physvol><volumeref ref="N"/></physvol>"#)
            ),
        ),
        &["bad.gdml:12", "solid `neg`"],
    );
    expect_error(
        &gdml(
            "",
            "",
            &world(r#"<physvol><volumeref ref="World"/></physvol>"#),
        ),
        &["unknown volume `World`"],
    );
    expect_error(
        "<gdml><solids/><structure/></gdml>",
        &["no <setup> with a <world"],
    );
    // A size beyond f32's range: the solid named, with its line.
    expect_error(
        &gdml(
            "",
            r#"<box name="huge" x="1" y="1e308" z="1"/>"#,
            &format!(
                r#"<volume name="H"><materialref ref="Air"/><solidref ref="huge"/></volume>{}"#,
                world(r#"<physvol><volumeref ref="H"/></physvol>"#)
            ),
        ),
        &["bad.gdml:12", "solid `huge`", "not finite"],
    );
    // A border surface naming a physical volume the file does not have: an error (a
    // warning with --lenient, the surface left out), as Geant4's reader refuses it.
    let surface = r#"<opticalsurface name="S" model="glisur" finish="polished" type="dielectric_metal" value="1"/>"#;
    let border = gdml(
        "",
        surface,
        &format!(
            r#"<volume name="G"><materialref ref="Glass"/><solidref ref="WorldBox"/></volume>{}
<bordersurface name="B" surfaceproperty="S"><physvolref ref="pv_g"/><physvolref ref="nope"/></bordersurface>"#,
            world(
                r#"<physvol name="pv_g"><volumeref ref="G"/><position name="p" x="0" y="0" z="0"/><scale name="s" x="0.1" y="0.1" z="0.1"/></physvol>"#
            )
        ),
    );
    expect_error(
        &border,
        &[
            "unknown physical volume `nope`",
            "bordersurface[name=B]/physvolref",
        ],
    );
    let lenient = GdmlOptions { lenient: true };
    let g = parse_gdml(&border, "test.gdml", &lenient).unwrap();
    assert!(g.logical_surfaces.is_empty());
    assert!(g
        .warnings
        .iter()
        .any(|w| w.contains("unknown physical volume `nope`")));
    expect_error(
        &gdml(
            r#"<variable name="i" value="0"/>"#,
            r#"<loop for="i" from="0" to="3" step="0"><box name="b" x="1" y="1" z="1"/></loop>"#,
            &world(""),
        ),
        &["loop step must be > 0"],
    );
    expect_error(
        &gdml(
            "",
            "",
            &world(r#"<physvol><file name="bad.gdml"/></physvol>"#),
        ),
        &["nest deeper"],
    );
    let missing = Path::new("/nonexistent/dir/x.gdml");
    let e = read_gdml(missing, &GdmlOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("/nonexistent/dir/x.gdml") && e.contains("cannot read"),
        "{e}"
    );
}

#[test]
fn lenient_skips_unsupported_elements_with_warnings() {
    let text = gdml("", r#"<blob name="x"/>"#, &world(""));
    let options = GdmlOptions { lenient: true };
    let g = parse_gdml(&text, "t.gdml", &options).unwrap();
    assert_eq!(g.warnings.len(), 1);
    assert!(g.warnings[0].contains("blob"));
    // Through the command line: strict fails, --lenient warns and succeeds.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("lenient.gdml");
    std::fs::write(&path, &text).unwrap();
    let run = |extra: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_hytrace"))
            .arg("info")
            .arg(&path)
            .args(extra)
            .output()
            .unwrap()
    };
    let strict = run(&[]);
    assert!(!strict.status.success());
    assert!(String::from_utf8_lossy(&strict.stderr).contains("unsupported solid <blob>"));
    let lenient = run(&["--lenient"]);
    assert!(
        lenient.status.success(),
        "{}",
        String::from_utf8_lossy(&lenient.stderr)
    );
    assert!(String::from_utf8_lossy(&lenient.stderr).contains("warning"));
}

/// A file using most of what the reader knows, the seed of the fuzz test.
fn fuzz_seed() -> String {
    gdml(
        r#"<variable name="i" value="0"/><constant name="w" value="50"/>
           <position name="p1" x="1" y="2" z="3" unit="cm"/>
           <rotation name="r1" x="10" y="20" z="30" unit="deg"/>
           <matrix name="RINDEX" coldim="2" values="1*eV 1.33 4*eV 1.34"/>"#,
        r#"<tube name="t" rmin="1" rmax="w" z="100" deltaphi="270" aunit="deg"/>
           <sphere name="s" rmax="30" deltaphi="360" deltatheta="180" aunit="deg"/>
           <subtraction name="ts"><first ref="t"/><second ref="s"/><positionref ref="p1"/><rotationref ref="r1"/></subtraction>
           <loop for="i" from="1" to="3" step="1"><box name="B[i]" x="10*i" y="10" z="10"/></loop>
           <polycone name="pc" deltaphi="360" aunit="deg"><zplane z="0" rmin="0" rmax="5"/><zplane z="10" rmin="0" rmax="7"/></polycone>
           <opticalsurface name="surf" model="glisur" finish="polished" type="dielectric_dielectric" value="1"/>"#,
        r#"<volume name="D"><materialref ref="Glass"/><solidref ref="ts"/></volume>
           <volume name="C"><materialref ref="Glass"/><solidref ref="B_0"/></volume>
           <assembly name="A"><physvol><volumeref ref="C"/><position name="q" x="100"/></physvol></assembly>
           <volume name="Row"><materialref ref="Air"/><solidref ref="B_2"/>
             <replicavol number="3"><volumeref ref="C"/><replicate_along_axis><direction x="1"/><width value="10" unit="mm"/><offset value="0" unit="mm"/></replicate_along_axis></replicavol>
           </volume>
           <volume name="World"><materialref ref="Air"/><solidref ref="WorldBox"/>
             <physvol name="d1" copynumber="7"><volumeref ref="D"/><positionref ref="p1"/><rotationref ref="r1"/></physvol>
             <physvol><volumeref ref="A"/><position name="q2" y="500"/></physvol>
             <physvol><volumeref ref="Row"/><position name="q3" z="-900"/></physvol>
             <loop for="i" from="0" to="4" step="1"><physvol><volumeref ref="C"/><position name="q4" x="-2000+100*i"/></physvol></loop>
           </volume>
           <skinsurface name="sk" surfaceproperty="surf"><volumeref ref="D"/></skinsurface>"#,
    )
}

fn mutate(seed: &str, rng: &mut XorShift64Star) -> String {
    let mut s = seed.to_string();
    for _ in 0..1 + rng.below(3) {
        let at = {
            let mut k = rng.below(s.len() + 1);
            while !s.is_char_boundary(k) {
                k -= 1;
            }
            k
        };
        match rng.below(8) {
            // Truncation.
            0 => s.truncate(at),
            // A bad number or expression where a digit was.
            1 => {
                if let Some(d) = s[at..].find(|c: char| c.is_ascii_digit()) {
                    let junk = ["NaN", "1e999", "-", "*", "(", "1/0", "--5", "-1e308*10"];
                    s.replace_range(at + d..at + d + 1, junk[rng.below(junk.len())]);
                }
            }
            // A reference pointing elsewhere (or at itself: a cycle).
            2 => {
                let names = [
                    "World", "D", "C", "A", "Row", "ts", "t", "B_0", "nope", "surf",
                ];
                if let Some(r) = s[at..].find("ref=\"") {
                    let start = at + r + 5;
                    if let Some(end) = s[start..].find('"') {
                        s.replace_range(start..start + end, names[rng.below(names.len())]);
                    }
                }
            }
            // Deep nesting of loops or elements.
            3 => {
                let depth = 1 + rng.below(3000);
                let open = "<loop for=\"i\" from=\"0\" to=\"9\" step=\"1\">".repeat(depth);
                let close = "</loop>".repeat(depth);
                s.insert_str(at, &format!("{open}{close}"));
            }
            // A deleted or duplicated span.
            4 => {
                let end = (at + rng.below(200)).min(s.len());
                let end = (end..=s.len()).find(|&e| s.is_char_boundary(e)).unwrap();
                if rng.below(2) == 0 {
                    s.replace_range(at..end, "");
                } else {
                    let span = s[at..end].to_string();
                    s.insert_str(end, &span);
                }
            }
            // Random bytes.
            5 => {
                let junk: String = (0..rng.below(20))
                    .map(|_| char::from(b"<>/=\"&;[]{}() \n\tabcxyz0129.-+*^"[rng.below(31)]))
                    .collect();
                s.insert_str(at, &junk);
            }
            // Huge counts and copies.
            6 => {
                for (from, to) in [
                    ("number=\"3\"", "number=\"1e9\""),
                    ("to=\"4\"", "to=\"1e12\""),
                    ("to=\"3\"", "to=\"99999999\""),
                ] {
                    s = s.replacen(from, to, 1);
                }
            }
            // A self-referencing boolean chain.
            _ => {
                let chain: String = (0..rng.below(400))
                    .map(|k| format!("<union name=\"u{}\"><first ref=\"u{k}\"/><second ref=\"u{k}\"/></union>", k + 1))
                    .collect();
                let chain = format!("<box name=\"u0\" x=\"1\" y=\"1\" z=\"1\"/>{chain}");
                if let Some(p) = s.find("</solids>") {
                    s.insert_str(p, &chain);
                }
            }
        }
    }
    s
}

/// Found by the 10^5-case fuzz run: a loop of ten million solids read for 20 s in 3 GB
/// before a later loop was refused; loops now stop at a million iterations in all.
#[test]
fn a_loop_of_millions_of_solids_is_refused_by_its_line() {
    let text = gdml(
        r#"<variable name="i" value="0"/>"#,
        r#"<loop for="i" from="1" to="9999*999" step="1"><box name="B[i]" x="10*i" y="10" z="10"/></loop>"#,
        r#"<volume name="World"><materialref ref="Air"/><solidref ref="WorldBox"/></volume>"#,
    );
    let t0 = std::time::Instant::now();
    let e = parse_gdml(&text, "big.gdml", &GdmlOptions::default()).unwrap_err();
    assert!(
        e.to_string().starts_with("big.gdml:") && e.to_string().contains("1000000 iterations"),
        "{e}"
    );
    assert!(t0.elapsed().as_secs() < 10, "{:?}", t0.elapsed());
}

#[test]
fn mutated_files_give_errors_never_panics_or_hangs() {
    let seed = fuzz_seed();
    // The seed itself is valid.
    let g = read(&seed);
    let f = gdml_to_foundry(&g).unwrap();
    assert_eq!(f.inst.len(), 1 + 1 + 1 + 1 + 3 + 5);
    let mut rng = XorShift64Star(0x9E37_79B9_7F4A_7C15);
    let started = std::time::Instant::now();
    let (mut ok, mut failed) = (0, 0);
    let cases = hytrace_testkit::fuzz_cases(1500);
    for case in 0..cases {
        let text = mutate(&seed, &mut rng);
        let t0 = std::time::Instant::now();
        match parse_gdml(&text, "fuzz.gdml", &GdmlOptions::default()) {
            Ok(g) => {
                // Building may fail (impossible solids, huge expansions) but not panic.
                let _ = gdml_to_foundry(&g);
                ok += 1;
            }
            Err(e) => {
                assert!(e.to_string().starts_with("fuzz.gdml:"), "{e}");
                failed += 1;
            }
        }
        assert!(
            t0.elapsed().as_secs() < 10,
            "case {case} took {:?}",
            t0.elapsed()
        );
    }
    eprintln!("{ok} read, {failed} rejected in {:?}", started.elapsed());
    assert!(
        ok > cases / 30 && failed > cases / 5,
        "{ok} read, {failed} rejected"
    );
}

#[test]
fn a_saved_gdml_foundry_loads_with_its_hierarchy_and_optics_and_scans_the_same() {
    use hytrace_foundry::Foundry;
    use hytrace_trace::scan::{rays_from_rows, scan, Precision};
    let f = gdml_to_foundry(&read(&fuzz_seed())).unwrap();
    let dir = tempfile::tempdir().unwrap();
    f.save(&dir.path().join("store")).unwrap();
    let back = Foundry::load(&dir.path().join("store")).unwrap();
    assert_eq!(back, f);
    assert!(back.inst_mother.iter().any(|m| m.index != u32::MAX));
    assert_eq!(back.optics.surfaces[0].name, "surf");
    // Rays from inside the world in every axis direction and a few oblique ones.
    let mut rows = Vec::new();
    for k in 0..60 {
        let a = k as f64 * 0.37;
        let d = [
            a.cos() * (0.3 * a).sin(),
            a.sin() * (0.3 * a).sin(),
            (0.3 * a).cos(),
        ];
        rows.push([
            10.0 * k as f64,
            -5.0 * k as f64,
            3.0,
            0.0,
            d[0],
            d[1],
            d[2],
            f64::INFINITY,
        ]);
    }
    let rays = rays_from_rows(&rows, "rays").unwrap();
    let (a, _) = scan(&f, &rays, Precision::F64).unwrap();
    let (b, _) = scan(&back, &rays, Precision::F64).unwrap();
    assert_eq!(a.hits, b.hits);
    assert_eq!(a.ids, b.ids);
    assert!(
        a.hits.iter().all(|h| h[3].is_finite()),
        "every ray leaves the world at least"
    );
}

#[test]
fn file_includes_place_another_files_world_with_its_own_names() {
    let dir = tempfile::tempdir().unwrap();
    let sub = gdml(
        r#"<constant name="size" value="40"/>"#,
        r#"<box name="cell" x="size" y="size" z="size"/><orb name="core" r="5"/>"#,
        r#"<volume name="Core"><materialref ref="Glass"/><solidref ref="core"/></volume>
           <volume name="Cell"><materialref ref="Air"/><solidref ref="cell"/>
             <physvol name="core_pv"><volumeref ref="Core"/><position name="c" x="10"/></physvol>
           </volume>
           <volume name="World"><materialref ref="Air"/><solidref ref="WorldBox"/></volume>"#,
    )
    .replace(r#"<world ref="World"/>"#, r#"<world ref="Cell"/>"#);
    std::fs::write(dir.path().join("sub.gdml"), sub).unwrap();
    let main = gdml(
        "",
        "",
        &world(
            r#"<physvol name="a"><file name="sub.gdml"/><position name="pa" z="100"/></physvol>
               <physvol name="b"><file name="sub.gdml" volname="Core"/><position name="pb" z="-100"/></physvol>"#,
        ),
    );
    let path = dir.path().join("main.gdml");
    std::fs::write(&path, main).unwrap();
    let f = load_gdml_scene(&path, &GdmlOptions::default()).unwrap();
    // World, the included cell with its core, and a second core on its own.
    assert_eq!(f.inst.len(), 4);
    let mut origins: Vec<[f64; 3]> = f
        .inst_tran
        .iter()
        .map(|t| t.apply_point([0.0; 3]))
        .collect();
    origins.sort_by(|a, b| a.partial_cmp(b).unwrap());
    assert_eq!(
        origins,
        vec![
            [0.0, 0.0, -100.0],
            [0.0, 0.0, 0.0],
            [0.0, 0.0, 100.0],
            [10.0, 0.0, 100.0]
        ]
    );
    // A missing include names the file.
    let bad = gdml(
        "",
        "",
        &world(r#"<physvol><file name="missing.gdml"/></physvol>"#),
    );
    let e = parse_gdml(&bad, &path.display().to_string(), &GdmlOptions::default()).unwrap_err();
    assert!(e.to_string().contains("missing.gdml"), "{e}");
}

/// Numerical hard case of the navigator: an origin a micrometre inside a 7 m volume's face
/// 5 m from the world's origin, moving out. In f32 the exit lies within the surface
/// tolerance of the start and is suppressed like a surface the ray starts on; the answer
/// must still be that exit (Geant4's step), not the next boundary or a miss.
#[test]
fn origin_a_micrometre_inside_a_far_face_moving_out_exits_there() {
    use hytrace_trace::scan::{rays_from_rows, scan, Precision};
    let text = gdml(
        "",
        r#"<box name="hall" x="7" y="7" z="7" lunit="m"/>"#,
        &format!(
            r#"<volume name="Hall"><materialref ref="Glass"/><solidref ref="hall"/></volume>{}"#,
            world(
                r#"<physvol name="h"><volumeref ref="Hall"/><position name="p" x="1.5" unit="m"/></physvol>"#
            )
        ),
    );
    let f = gdml_to_foundry(&read(&text)).unwrap();
    // The face at x = 5000 mm; start 1e-3 mm inside it.
    let rows = vec![
        [4999.999, 10.0, -20.0, 0.0, 1.0, 0.0, 0.0, f64::INFINITY],
        [4999.999, 10.0, -20.0, 0.0, 0.6, 0.8, 0.0, f64::INFINITY],
    ];
    let rays = rays_from_rows(&rows, "rays").unwrap();
    for precision in [Precision::F32, Precision::F64] {
        let (r, _) = scan(&f, &rays, precision).unwrap();
        for (k, want) in [0.001, 0.001 / 0.6].into_iter().enumerate() {
            let t = r.hits[k][3];
            let band = if precision == Precision::F32 {
                0.05
            } else {
                1e-9
            };
            assert!(
                (t - want).abs() <= band,
                "{precision:?} ray {k}: t {t}, want {want}"
            );
            assert_eq!(r.ids[k][0], 1, "the hall's own surface");
        }
    }
}
