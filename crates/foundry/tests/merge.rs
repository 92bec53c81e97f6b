//! `Foundry::append`: a Foundry appended to another, placed any number of times, equals the
//! two built into one Foundry, and every relocated index reaches the same record content.

use hytrace_foundry::optics::{Boundary, Material, Medium, OpticalSurface};
use hytrace_foundry::{
    Brick, CsgTree, Foundry, Node, Plane, PrimKind, Transform64, Triangle, TypeCode,
    COMPLEMENT_BIT, UNSET,
};

/// Where a sample's shared records start in the Foundry they were added to.
struct Base {
    /// CSG tree, single sphere (the world), mesh, volume.
    solids: [u32; 4],
    boundary: u32,
    volume: u32,
}

fn node(code: TypeCode, param: [f32; 4], transform: u32, boundary: u32) -> Node {
    Node {
        param,
        typecode: code as u32,
        transform,
        boundary,
        aabb: [-50.0, -50.0, -50.0, 50.0, 50.0, 50.0],
        ..Node::default()
    }
}

/// A tree using every index a node can hold: `(box (transformed, complemented) + list of
/// two spheres) - convex polyhedron (transformed, six planes)`, with node boundaries.
fn csg_tree(size: f32, boundary: u32) -> CsgTree {
    let index = |i: u32| f32::from_bits(i);
    let operator = |code| node(code, [0.0; 4], 0, UNSET);
    let cube = [
        [1.0, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, -1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
    ];
    CsgTree {
        nodes: vec![
            operator(TypeCode::Difference),
            operator(TypeCode::Union),
            node(
                TypeCode::ConvexPolyhedron,
                [index(0), index(6), 0.0, 0.0],
                2,
                boundary + 1,
            ),
            node(
                TypeCode::Box3,
                [size, size, size, 0.0],
                1 | COMPLEMENT_BIT,
                boundary,
            ),
            node(
                TypeCode::ListContiguous,
                [index(0), index(2), 0.0, 0.0],
                0,
                UNSET,
            ),
            Node::default(),
            Node::default(),
        ],
        members: vec![
            node(TypeCode::Sphere, [0.0, 0.0, 0.0, size / 2.0], 0, boundary),
            node(TypeCode::Sphere, [0.0, 0.0, 0.0, size / 3.0], 3, UNSET),
        ],
        transforms: vec![
            Transform64::rotation([0.0, 0.0, 1.0], 0.3),
            Transform64::translation([1.0, 2.0, size as f64]),
            Transform64::translation([size as f64 / 4.0, 0.0, 0.0]),
        ],
        planes: cube
            .iter()
            .map(|n| Plane {
                plane: [n[0], n[1], n[2], size],
            })
            .collect(),
        ..CsgTree::default()
    }
}

/// Adds one sample's shared records (solids of every prim kind, optics) to `f`; `tag`
/// tells samples apart.
fn sample_records(f: &mut Foundry, tag: &str, size: f32) -> Base {
    let material = f.optics.materials.len() as u32;
    let surface = f.optics.surfaces.len() as u32;
    let boundary = f.optics.boundaries.len() as u32;
    let volume = f.optics.volumes.len() as u32;
    for name in ["air", "iron"] {
        f.optics.materials.push(Material {
            name: format!("{tag}/{name}"),
            properties: Vec::new(),
        });
    }
    f.optics.surfaces.push(OpticalSurface {
        name: format!("{tag}/mirror"),
        ..OpticalSurface::default()
    });
    f.optics.boundaries.extend([
        Boundary {
            outer_material: UNSET,
            outer_surface: UNSET,
            inner_surface: UNSET,
            inner_material: material,
        },
        Boundary {
            outer_material: material,
            outer_surface: surface,
            inner_surface: UNSET,
            inner_material: material + 1,
        },
        Boundary {
            outer_material: material + 1,
            outer_surface: UNSET,
            inner_surface: surface,
            inner_material: material,
        },
    ]);
    for name in ["world", "detector", "panel"] {
        f.optics.volumes.push(format!("{tag}/{name}"));
    }

    let mut s = f.begin_solid(&format!("{tag}/tree"));
    s.add_csg(csg_tree(size, boundary + 1), 11, boundary + 2)
        .unwrap();
    let tree = s.finish(1).unwrap();

    let mut s = f.begin_solid(&format!("{tag}/world"));
    let world_sphere = node(TypeCode::Sphere, [0.0, 0.0, 0.0, 100.0 * size], 0, UNSET);
    let world_tree = CsgTree {
        nodes: vec![world_sphere],
        ..CsgTree::default()
    };
    s.add_csg(world_tree, 12, UNSET).unwrap();
    let world = s.finish(2).unwrap();

    let triangle = |z: f32| Triangle {
        v: [[0.0, 0.0, z, 0.0], [size, 0.0, z, 0.0], [0.0, size, z, 0.0]],
    };
    let mut s = f.begin_solid(&format!("{tag}/mesh"));
    s.add_mesh(&[triangle(0.0), triangle(1.0)], None, 13, boundary)
        .unwrap();
    let shifted = Transform64::translation([0.0, 0.0, size as f64]);
    s.add_mesh(&[triangle(2.0)], Some(shifted), 14, UNSET)
        .unwrap();
    let mesh = s.finish(3).unwrap();

    let brick = |x: i32| Brick {
        origin: [x, 0, 0],
        atlas_slot: x as u32,
        value_max: size,
        aabb: [x as f32, 0.0, 0.0, x as f32 + 8.0, 8.0, 8.0],
        active_voxels: 10,
        size: 8,
        ..Brick::default()
    };
    let mut s = f.begin_solid(&format!("{tag}/fog"));
    let scale = Transform64::translation([-8.0, -4.0, -4.0]);
    let prim = s
        .add_volume(&[brick(0), brick(8)], Some(scale), 15)
        .unwrap();
    let fog = s.finish(4).unwrap();
    f.optics.media.push(Medium {
        prim: prim as u32,
        source: format!("sphere:{size},1"),
        grid: None,
        density_scale: 0.5,
        format: "f32".into(),
        albedo: 0.25,
        g: 0.5,
    });
    Base {
        solids: [tree, world, mesh, fog],
        boundary,
        volume,
    }
}

/// Places a sample's hierarchy: a world, two daughters, a granddaughter and one unset
/// instance, each transform after `placement` when given.
fn sample_instances(f: &mut Foundry, base: &Base, placement: Option<&Transform64>) {
    let first = f.inst.len() as u32;
    let [tree, world, mesh, fog] = base.solids;
    let (b, v) = (base.boundary, base.volume);
    let rows = [
        // solid, transform, identity, copy, boundary, mother (relative)
        (world, Transform64::IDENTITY, v, 0, b, None),
        (
            tree,
            Transform64::translation([10.0, -3.0, 2.0])
                .compose(&Transform64::rotation([1.0, 1.0, 0.0], 0.7)),
            v + 1,
            7,
            b + 1,
            Some(0),
        ),
        (
            mesh,
            Transform64::translation([-20.0, 0.0, 0.0]),
            v + 2,
            8,
            b + 2,
            Some(0),
        ),
        (
            fog,
            Transform64::rotation([0.0, 1.0, 0.0], -0.4),
            UNSET,
            9,
            UNSET,
            Some(1),
        ),
        (
            tree,
            Transform64::translation([0.0, 0.0, 300.0]),
            v + 1,
            10,
            b + 1,
            None,
        ),
    ];
    for (solid, t, identity, copy, boundary, mother) in rows {
        let world_t = placement.map_or(t, |p| p.compose(&t));
        let i = f.add_instance(solid, world_t, identity, copy).unwrap();
        f.inst[i].boundary = boundary;
        f.inst_mother[i].index = mother.map_or(UNSET, |m| first + m);
    }
}

/// A Foundry holding one sample, placed at the origin.
fn sample(tag: &str, size: f32) -> Foundry {
    let mut f = Foundry::new();
    let base = sample_records(&mut f, tag, size);
    sample_instances(&mut f, &base, None);
    f.validate().unwrap();
    f
}

fn placements() -> Vec<Transform64> {
    vec![
        Transform64::translation([1000.0, 0.0, 0.0]),
        Transform64::translation([0.0, -500.0, 20.0])
            .compose(&Transform64::rotation([0.2, 0.0, 1.0], 1.1)),
        // A reflection: placements may mirror, as GDML's do.
        Transform64 {
            rows: [
                [-1.0, 0.0, 0.0, 5.0],
                [0.0, 1.0, 0.0, 0.0],
                [0.0, 0.0, 1.0, 0.0],
                [0.0, 0.0, 0.0, 1.0],
            ],
        },
    ]
}

#[test]
fn appending_equals_building_together() {
    for copies in 0..=3 {
        let placed = &placements()[..copies];
        let mut together = Foundry::new();
        let a = sample_records(&mut together, "a", 3.0);
        sample_instances(&mut together, &a, None);
        let b = sample_records(&mut together, "b", 5.0);
        for p in placed {
            sample_instances(&mut together, &b, Some(p));
        }
        together.validate().unwrap();

        let mut merged = sample("a", 3.0);
        let (a_solids, a_inst) = (merged.solid.len() as u32, merged.inst.len() as u32);
        let a_boundaries = merged.optics.boundaries.len() as u32;
        let other = sample("b", 5.0);
        let appended = merged.append(&other, placed).unwrap();
        merged.validate().unwrap();
        assert_eq!(merged, together, "{copies} copies");

        let n = other.inst.len() as u32;
        assert_eq!(
            appended.solids,
            a_solids..a_solids + other.solid.len() as u32
        );
        assert_eq!(
            appended.boundaries,
            a_boundaries..a_boundaries + other.optics.boundaries.len() as u32
        );
        let expected: Vec<_> = (0..copies as u32)
            .map(|k| a_inst + k * n..a_inst + (k + 1) * n)
            .collect();
        assert_eq!(appended.instances, expected);
    }
}

#[test]
fn appending_to_an_empty_foundry_at_the_identity_gives_the_original() {
    let original = sample("solo", 2.0);
    let mut f = Foundry::new();
    let appended = f.append(&original, &[Transform64::IDENTITY]).unwrap();
    assert_eq!(f, original);
    assert_eq!(appended.instances, vec![0..original.inst.len() as u32]);
    // Appending nothing changes nothing.
    f.append(&Foundry::new(), &[Transform64::IDENTITY]).unwrap();
    assert_eq!(f, original);
}

/// What instance `i` of `f` is, through every index it holds, without the indices
/// themselves and without its world transform: its solid's prims with their nodes (list
/// members and planes included), transforms, triangles, bricks and media, its boundaries'
/// material and surface names, its volume name and copy number, and its mother's identity.
fn describe(f: &Foundry, i: usize) -> String {
    let material = |m: u32| f.optics.materials.get(m as usize).map(|m| m.name.clone());
    let surface = |s: u32| f.optics.surfaces.get(s as usize).map(|s| s.name.clone());
    let boundary = |b: u32| {
        f.optics.boundaries.get(b as usize).map(|b| {
            (
                material(b.outer_material),
                surface(b.outer_surface),
                surface(b.inner_surface),
                material(b.inner_material),
            )
        })
    };
    let transform = |t: u32| (t > 0).then(|| f.tran[t as usize - 1]);
    let describe_node = |n: &Node| {
        if n.typecode == TypeCode::Zero as u32 {
            return format!("{n:?}");
        }
        let mut n = *n;
        let t = transform(n.transform & !COMPLEMENT_BIT);
        let b = boundary(n.boundary);
        let first = n.param[0].to_bits() as usize;
        let count = n.param[1].to_bits() as usize;
        let indexed = match TypeCode::from_u32(n.typecode) {
            Some(TypeCode::ConvexPolyhedron) => format!("{:?}", &f.plan[first..first + count]),
            Some(c) if c.is_list() => format!(
                "{:?}",
                &f.node[first..first + count]
                    .iter()
                    .map(|m| (
                        m.param,
                        m.typecode,
                        transform(m.transform & !COMPLEMENT_BIT),
                        boundary(m.boundary)
                    ))
                    .collect::<Vec<_>>()
            ),
            _ => String::new(),
        };
        if !indexed.is_empty() {
            n.param[0] = 0.0;
        }
        (n.transform, n.boundary) = (n.transform & COMPLEMENT_BIT, 0);
        format!("{n:?} {t:?} {b:?} {indexed}")
    };
    let inst = &f.inst[i];
    let s = &f.solid[inst.solid as usize];
    let mut out = format!(
        "{} {:?} {} {:?} {:?}\n",
        f.solid_names[inst.solid as usize],
        (
            s.label,
            s.num_prim,
            s.content,
            s.max_height,
            s.aabb,
            s.extent,
            s.identity
        ),
        inst.copy_number,
        f.optics.volumes.get(inst.identity as usize),
        boundary(inst.boundary),
    );
    let mother = f.inst_mother[i].index;
    if mother != UNSET {
        let m = &f.inst[mother as usize];
        out += &format!(
            "in {:?} {}\n",
            f.optics.volumes.get(m.identity as usize),
            m.copy_number
        );
    }
    for p in 0..s.num_prim {
        let index = (s.prim_offset + p) as usize;
        let prim = &f.prim[index];
        out += &format!(
            "prim {:?} {:?} {:?}\n",
            (
                prim.kind,
                prim.num_node,
                prim.item_count,
                prim.identity,
                prim.aabb
            ),
            transform(prim.transform),
            boundary(prim.boundary),
        );
        let nodes = &f.node[prim.node_offset as usize..][..prim.num_node as usize];
        for n in nodes {
            out += &describe_node(n);
            out += "\n";
        }
        let items = prim.item_offset as usize..(prim.item_offset + prim.item_count) as usize;
        if prim.kind == PrimKind::Mesh as u32 {
            out += &format!("{:?}\n", &f.tri[items]);
        } else if prim.kind == PrimKind::Volume as u32 {
            for b in &f.brick[items] {
                assert_eq!(b.prim as usize, index, "a brick names its prim");
                out += &format!("{:?}\n", Brick { prim: 0, ..*b });
            }
            let medium = f.optics.media.iter().find(|m| m.prim as usize == index);
            out += &format!(
                "{:?}\n",
                medium.map(|m| Medium {
                    prim: 0,
                    ..m.clone()
                })
            );
        }
    }
    out
}

#[test]
fn every_relocated_index_reaches_the_same_content() {
    let mut merged = sample("a", 3.0);
    let before = merged.clone();
    let other = sample("b", 5.0);
    let placed = placements();
    let appended = merged.append(&other, &placed).unwrap();
    merged.validate().unwrap();
    // What was there is untouched.
    for i in 0..before.inst.len() {
        assert_eq!(describe(&merged, i), describe(&before, i));
    }
    assert_eq!(merged.node[..before.node.len()], before.node[..]);
    assert_eq!(merged.prim[..before.prim.len()], before.prim[..]);
    for (k, (range, p)) in appended.instances.iter().zip(&placed).enumerate() {
        for i in 0..other.inst.len() {
            let j = range.start as usize + i;
            assert_eq!(
                describe(&merged, j),
                describe(&other, i),
                "copy {k}, instance {i}"
            );
            let want = p.compose(&other.inst_tran[i].to_transform());
            assert_eq!(merged.inst_tran[j].to_transform(), want);
            let mother = other.inst_mother[i].index;
            let want = if mother == UNSET {
                UNSET
            } else {
                range.start + mother
            };
            assert_eq!(merged.inst_mother[j].index, want);
        }
    }
}

#[test]
fn a_bad_placement_is_refused_and_leaves_the_foundry_unchanged() {
    let mut f = sample("a", 3.0);
    let before = f.clone();
    let singular = Transform64 {
        rows: [[0.0; 4], [0.0; 4], [0.0; 4], [0.0, 0.0, 0.0, 1.0]],
    };
    let mut projective = Transform64::IDENTITY;
    projective.rows[3][0] = 1.0;
    let mut nan = Transform64::IDENTITY;
    nan.rows[0][3] = f64::NAN;
    for bad in [singular, projective, nan] {
        let e = f
            .append(&sample("b", 1.0), &[Transform64::IDENTITY, bad])
            .unwrap_err()
            .to_string();
        assert!(e.contains("placement 1"), "{e}");
        assert_eq!(f, before);
    }
}
