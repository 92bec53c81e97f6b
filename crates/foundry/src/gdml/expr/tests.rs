//! Tests of `expr.rs`.

use super::*;
use hytrace_testkit::{Random, XorShift64};
use std::collections::HashMap;

#[derive(Default)]
struct TestScope {
    scalars: HashMap<&'static str, f64>,
    matrices: HashMap<&'static str, (Vec<f64>, usize, usize)>,
}

impl Scope for TestScope {
    fn scalar(&self, name: &str) -> Option<f64> {
        self.scalars.get(name).copied()
    }
    fn matrix(&self, name: &str) -> Option<(&[f64], usize, usize)> {
        self.matrices
            .get(name)
            .map(|(data, rows, columns)| (data.as_slice(), *rows, *columns))
    }
}

fn scope() -> TestScope {
    let mut s = TestScope::default();
    s.scalars.insert("x", 3.0);
    s.scalars.insert("y", 0.5);
    s.scalars.insert("zero", 0.0);
    s.scalars.insert("huge", 1e300);
    s.scalars.insert("bad", f64::NAN);
    s.matrices
        .insert("m", (vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0], 2, 3));
    s.matrices.insert("v", (vec![10.0, 20.0, 30.0], 1, 3));
    s.matrices.insert("c", (vec![7.0, 8.0, 9.0], 3, 1));
    s.matrices.insert("one", (vec![42.0], 1, 1));
    s.matrices
        .insert("my_m_2", (vec![1.5, 2.5, 3.5, 4.5], 2, 2));
    s.matrices.insert("short", (vec![1.0, 2.0], 2, 2)); // lies about its size
    s
}

fn close(a: f64, b: f64) -> bool {
    a == b || (a - b).abs() <= 1e-14 * a.abs().max(b.abs())
}

#[test]
fn values() {
    let s = scope();
    // (expression, value computed by hand or with float64 outside this module)
    let table: &[(&str, f64)] = &[
        ("1", 1.0),
        ("1.5", 1.5),
        (".5", 0.5),
        ("1.", 1.0),
        ("1e-3", 0.001),
        ("2.E+4", 20000.0),
        ("6.02e23", 6.02e23),
        ("007", 7.0),
        ("  7\t", 7.0),
        (" 1 +\t2\n*3\r", 7.0),
        ("2*(HALFPI+0.2*PI)", 4.39822971502571),
        ("10*cm", 100.0),
        ("1*m/2", 500.0),
        ("30*deg", 0.5235987755982988),
        ("180*degree", std::f64::consts::PI),
        ("2*pi - twopi", 0.0),
        ("halfpi*2 - PI", 0.0),
        ("TWOPI", std::f64::consts::TAU),
        ("-2^2", -4.0),
        ("-2**2", -4.0),
        ("2^3^2", 512.0),
        ("2**3**2", 512.0),
        ("(2^3)^2", 64.0),
        ("2^-1", 0.5),
        ("2^-3^2", 0.001953125),
        ("2 ^ 0.5 ^ 2", 1.189207115002721),
        ("2*-3", -6.0),
        ("2*-3^2", -18.0),
        ("-3^2+1", -8.0),
        ("1-2^2", -3.0),
        ("--2", 2.0),
        ("-+-2", 2.0),
        ("+2", 2.0),
        ("- - - 2", -2.0),
        ("1+2*3", 7.0),
        ("(1+2)*3", 9.0),
        ("10-4-3", 3.0),
        ("64/4/2", 8.0),
        ("1/4*2", 0.5),
        ("2*3/4", 1.5),
        ("atan2(1,1)", std::f64::consts::FRAC_PI_4),
        ("atan2(0, -1)", std::f64::consts::PI),
        ("min(3,max(1,2))", 2.0),
        ("max(-1, -2)", -1.0),
        ("abs(-3)", 3.0),
        ("fabs(-2.5)", 2.5),
        ("pow(2,10)", 1024.0),
        ("sqrt(16)", 4.0),
        ("sqrt (2)", std::f64::consts::SQRT_2),
        ("fmod(7,3)", 1.0),
        ("fmod(-7,3)", -1.0),
        ("fmod(7.5, 2)", 1.5),
        ("floor(-1.5)", -2.0),
        ("ceil(1.2)", 2.0),
        ("int(-1.7)", -1.0),
        ("int(1.7)", 1.0),
        ("exp(0)", 1.0),
        ("log(e)", 1.0),
        ("log10(1000)", 3.0),
        ("sin(pi/2)", 1.0),
        ("cos(0)", 1.0),
        ("tan(0)", 0.0),
        ("asin(1)", std::f64::consts::FRAC_PI_2),
        ("acos(1)", 0.0),
        ("atan(1)", std::f64::consts::FRAC_PI_4),
        ("sinh(0) + cosh(0) + tanh(0)", 1.0),
        ("sin(x)^2 + cos(x)^2", 1.0),
        ("1<2", 1.0),
        ("2<1", 0.0),
        ("1<=1", 1.0),
        ("2>=3", 0.0),
        ("3>2", 1.0),
        ("3 > 3", 0.0),
        ("1==1", 1.0),
        ("1!=1", 0.0),
        ("1 != 2", 1.0),
        ("1+1==2", 1.0),
        ("1<2==1", 1.0),
        ("2==2<1", 0.0),
        ("1||0&&0", 1.0),
        ("0&&1||1", 1.0),
        ("0||0", 0.0),
        ("2&&3", 1.0),
        ("0.5&&0", 0.0),
        ("1<2<3", 1.0),
        ("3>2>1", 0.0),
        ("x < 4 && y > 0", 1.0),
        ("x*2", 6.0),
        ("x^2", 9.0),
        ("-x^2", -9.0),
        ("x/y", 6.0),
        ("zero", 0.0),
        ("mm", 1.0),
        ("cm3", 1000.0),
        ("L", 1e6),
        ("MeV", 1.0),
        ("GeV/MeV", 1000.0),
        ("eV", 1e-6),
        ("g/cm3", 6.241509074460762e18),
        ("kg", 6.241509074460762e24),
        ("joule", 6241509074460.763),
        ("c_light", 299.792458),
        ("hbarc", 1.9732698045930245e-10),
        ("m[1,1]", 1.0),
        ("m[2,3]", 6.0),
        ("m[1,3]", 3.0),
        ("m[2,1]", 4.0),
        ("m [ 2 , 2 ]", 5.0),
        ("m[x-1, x]", 6.0),
        ("m[1+1,1]", 4.0),
        ("m[m[1,2], m[1,1]]", 4.0),
        ("v[2]", 20.0),
        ("v[ 1 ] + v[3]", 40.0),
        ("c[3]", 9.0),
        ("one[1]", 42.0),
        ("my_m_2[2,1]", 3.5),
        ("m_1_2", 6.0),
        ("m_0_0", 1.0),
        ("v_2", 30.0),
        ("c_0", 7.0),
        ("one_0", 42.0),
        ("my_m_2_1_0", 3.5),
        ("-v[1]^2", -100.0),
        ("2*v[1]", 20.0),
    ];
    for &(text, expected) in table {
        match evaluate(text, &s) {
            Ok(value) => assert!(
                close(value, expected),
                "{text:?} gave {value}, expected {expected}"
            ),
            Err(e) => panic!("{text:?} failed: {e}"),
        }
    }
}

#[test]
fn unary_signs_follow_clhep_on_zero() {
    // CLHEP computes -x as 0 - x, so a negated zero is +0.
    let s = scope();
    assert_eq!(evaluate("atan2(-0, -1)", &s), Ok(std::f64::consts::PI));
    assert_eq!(evaluate("atan2(-zero, -1)", &s), Ok(std::f64::consts::PI));
    assert_eq!(evaluate("-(-0)", &s).map(f64::is_sign_positive), Ok(true));
    assert_eq!(evaluate("--0", &s).map(f64::is_sign_positive), Ok(true));
}

#[test]
fn scope_shadows_constants_and_units() {
    let mut s = TestScope::default();
    s.scalars.insert("cm", 2.0);
    s.scalars.insert("pi", 3.0);
    s.scalars.insert("m_0_0", 7.0);
    s.matrices.insert("m", (vec![1.0, 2.0, 3.0, 4.0], 2, 2));
    assert_eq!(evaluate("10*cm", &s), Ok(20.0));
    assert_eq!(evaluate("pi", &s), Ok(3.0));
    assert_eq!(evaluate("m_0_0", &s), Ok(7.0));
    assert_eq!(evaluate("m_1_1", &s), Ok(4.0));
    assert_eq!(evaluate("10*mm", &s), Ok(10.0));
}

#[test]
fn brackets_fall_back_to_geant4_element_names() {
    // A matrix defined only through its element constants, as Geant4 stores it.
    let mut s = TestScope::default();
    s.scalars.insert("t_0", 5.0);
    s.scalars.insert("t_1_2", 6.0);
    assert_eq!(evaluate("t[1]", &s), Ok(5.0));
    assert_eq!(evaluate("t[2,3]", &s), Ok(6.0));
    let e = evaluate("t[3]", &s).unwrap_err();
    assert!(e.message.contains("unknown matrix \"t\""), "{e}");
}

#[test]
fn empty_scope_and_units() {
    assert_eq!(evaluate("2*km + 3*m", &()), Ok(2_003_000.0));
    assert_eq!(unit("mm"), Some(1.0));
    assert_eq!(unit("foo"), None);
    assert_eq!(unit("pi"), None);
    assert_eq!(unit("pascal"), unit("hep_pascal"));
    // Values computed with float64 from CLHEP's definitions.
    let table: &[(&str, f64)] = &[
        ("e_SI", 1.602176634e-19),
        ("coulomb", 6.241509074460763e18),
        ("joule", 6241509074460.763),
        ("kg", 6.241509074460762e24),
        ("atmosphere", 632420906.9697368),
        ("bar", 624150907.4460763),
        ("ohm", 1.602176634e-16),
        ("tesla", 0.001),
        ("henry", 1.602176634e-07),
        ("farad", 6.241509074460764e24),
        ("year", 3.1536e16),
        ("parsec", 3.0856775807e19),
        ("pc", 3.0856775807e19),
        ("gray", 1e-12),
        ("um", 1e-3),
        ("nm", 1e-6),
        ("angstrom", 1e-7),
        ("fermi", 1e-12),
        ("barn", 1e-22),
        ("liter", 1e6),
        ("mL", 1e3),
        ("s", 1e9),
        ("ms", 1e6),
        ("us", 1e3),
        ("ps", 1e-3),
        ("minute", 6e10),
        ("hertz", 1e-9),
        ("megahertz", 1e-3),
        ("keV", 1e-3),
        ("TeV", 1e6),
        ("PeV", 1e9),
        ("millielectronvolt", 1e-9),
        ("mrad", 1e-3),
        ("deg", 0.017453292519943295),
        ("perCent", 0.01),
        ("perMillion", 1e-6),
        ("kelvin", 1.0),
        ("mole", 1.0),
        ("candela", 1.0),
        ("eplus", 1.0),
        ("volt", 1e-6),
        ("kilovolt", 1e-3),
        ("megavolt", 1.0),
        ("gauss", 1e-7),
        ("kilogauss", 1e-4),
        ("ampere", 6.241509074460763e9),
        ("curie", 37.0),
        ("lux", 1e-6),
    ];
    for &(name, expected) in table {
        let value = unit(name).unwrap_or_else(|| panic!("{name} is not a unit"));
        assert!(
            close(value, expected),
            "{name} = {value}, expected {expected}"
        );
    }
    // Every unit the brief lists exists.
    for name in [
        "millimeter",
        "mm",
        "millimeter2",
        "mm2",
        "millimeter3",
        "mm3",
        "centimeter",
        "cm",
        "cm2",
        "cm3",
        "meter",
        "m",
        "m2",
        "m3",
        "kilometer",
        "km",
        "km2",
        "km3",
        "parsec",
        "pc",
        "micrometer",
        "um",
        "nanometer",
        "nm",
        "angstrom",
        "fermi",
        "barn",
        "millibarn",
        "microbarn",
        "nanobarn",
        "picobarn",
        "liter",
        "L",
        "dL",
        "cL",
        "mL",
        "radian",
        "rad",
        "milliradian",
        "mrad",
        "degree",
        "deg",
        "steradian",
        "sr",
        "nanosecond",
        "ns",
        "second",
        "s",
        "millisecond",
        "ms",
        "microsecond",
        "us",
        "picosecond",
        "ps",
        "minute",
        "hour",
        "day",
        "year",
        "hertz",
        "kilohertz",
        "megahertz",
        "electronvolt",
        "eV",
        "kiloelectronvolt",
        "keV",
        "megaelectronvolt",
        "MeV",
        "gigaelectronvolt",
        "GeV",
        "teraelectronvolt",
        "TeV",
        "petaelectronvolt",
        "PeV",
        "millielectronvolt",
        "joule",
        "kilogram",
        "kg",
        "gram",
        "g",
        "milligram",
        "mg",
        "watt",
        "newton",
        "hep_pascal",
        "pascal",
        "bar",
        "atmosphere",
        "ampere",
        "milliampere",
        "microampere",
        "nanoampere",
        "megavolt",
        "kilovolt",
        "volt",
        "ohm",
        "farad",
        "millifarad",
        "microfarad",
        "picofarad",
        "weber",
        "tesla",
        "gauss",
        "kilogauss",
        "henry",
        "kelvin",
        "mole",
        "becquerel",
        "curie",
        "kilobecquerel",
        "megabecquerel",
        "gigabecquerel",
        "millicurie",
        "microcurie",
        "gray",
        "kilogray",
        "milligray",
        "microgray",
        "sievert",
        "millisievert",
        "microsievert",
        "candela",
        "lumen",
        "lux",
        "perCent",
        "perThousand",
        "perMillion",
        "eplus",
        "e_SI",
        "coulomb",
    ] {
        let value = unit(name).unwrap_or_else(|| panic!("{name} is not a unit"));
        assert!(value.is_finite() && value > 0.0, "{name} = {value}");
        assert_eq!(evaluate(name, &()), Ok(value), "{name}");
    }
}

#[test]
fn physical_constants() {
    let s = TestScope::default();
    let table: &[(&str, f64)] = &[
        ("electron_mass_c2", 0.51099891),
        ("proton_mass_c2", 938.272013),
        ("Avogadro", 6.02214076e23),
        ("fine_structure_const", 0.0072973525693),
        ("classic_electr_radius", 2.8179403262e-12),
        ("Bohr_radius", 5.29177210903e-8),
        ("k_Boltzmann", 8.617333e-11),
        ("STP_Temperature", 273.15),
        ("electron_charge", -1.0),
    ];
    for &(name, expected) in table {
        let value = evaluate(name, &s).unwrap();
        // Electron mass differs between CLHEP (PDG 2008) and CODATA 2018 at 1e-7.
        assert!(
            (value - expected).abs() <= 1e-6 * expected.abs(),
            "{name} = {value}, expected {expected}"
        );
    }
}

/// (expression, text the message must contain, 1-based column)
const ERRORS: &[(&str, &str, usize)] = &[
    ("", "empty expression", 1),
    ("   ", "empty expression", 1),
    ("2*(x+", "unexpected end", 6),
    ("-", "unexpected end", 2),
    ("foo", "unknown name \"foo\"", 1),
    ("1 + foo * 2", "unknown name \"foo\"", 5),
    ("sin", "unknown name \"sin\"", 1),
    ("foo(1)", "unknown function \"foo\"", 1),
    ("x(1)", "unknown function \"x\"", 1),
    ("sin(1,2)", "sin() takes 1 argument but 2 given", 1),
    ("1+atan2(1)", "atan2() takes 2 arguments but 1 given", 3),
    ("max()", "max() takes 2 arguments but 0 given", 1),
    ("sin(1,)", "unexpected \")\"", 7),
    ("sin(,1)", "unexpected \",\"", 5),
    ("sin(1", "expected \",\" or \")\" but found end", 6),
    ("sin(1 2)", "expected \",\" or \")\" but found \"2\"", 7),
    ("1 2", "unexpected \"2\"", 3),
    ("2mm", "unexpected \"m\"", 2),
    ("2(3)", "unexpected \"(\"", 2),
    ("1e", "bad number \"1e\"", 1),
    ("3*1e+", "bad number \"1e+\"", 3),
    (".", "bad number", 1),
    ("1.2.3", "unexpected \".\"", 4),
    ("1e400", "out of range", 1),
    ("1/0", "division by zero", 2),
    ("1/(x-3)", "division by zero", 2),
    ("1/zero", "division by zero", 2),
    ("sqrt(-1)", "sqrt() evaluates to NaN", 1),
    ("2*log(0)", "log() evaluates to -inf", 3),
    ("fmod(1,0)", "fmod() evaluates to NaN", 1),
    ("exp(1000)", "exp() evaluates to inf", 1),
    ("1e308*10", "\"*\" evaluates to inf", 6),
    ("huge*huge", "\"*\" evaluates to inf", 5),
    ("(-8)^(1/3)", "power evaluates to NaN", 5),
    ("0^-1", "power evaluates to inf", 2),
    ("bad", "\"bad\" evaluates to NaN", 1),
    (
        "(1+2",
        "expected \")\" to close \"(\" at column 1 but found end",
        5,
    ),
    ("((1)", "expected \")\"", 5),
    ("1+2)", "unmatched \")\"", 4),
    (")", "unexpected \")\"", 1),
    ("m[1]", "matrix \"m\" is 2x3 and takes 2 indices, not 1", 1),
    ("v[1,1]", "takes 1 index, not 2", 1),
    ("m[1,2,3]", "takes 2 indices, not 3", 1),
    ("m[3,1]", "index 3 is out of range 1..=2 of matrix \"m\"", 3),
    ("m[1, 4]", "index 4 is out of range 1..=3", 6),
    ("m[1.5,1]", "matrix index 1.5 is not a positive integer", 3),
    ("m[0,1]", "matrix index 0 is not a positive integer", 3),
    ("v[-1]", "matrix index -1 is not a positive integer", 3),
    ("v[4]", "index 4 is out of range 1..=3", 3),
    ("v[1e300]", "is out of range", 3),
    ("short[2,2]", "has 2 elements", 1),
    ("x[1]", "\"x\" is not a matrix", 1),
    ("mm[1]", "\"mm\" is not a matrix", 1),
    ("q[1]", "unknown matrix \"q\"", 1),
    ("m[1,1", "expected \",\" or \"]\" but found end", 6),
    ("m[]", "unexpected \"]\"", 3),
    ("m_2_0", "unknown name \"m_2_0\"", 1),
    ("v_3", "unknown name \"v_3\"", 1),
    ("v_01", "unknown name \"v_01\"", 1),
    ("m_1", "unknown name \"m_1\"", 1),
    ("1 | 2", "unexpected \"|\"", 3),
    ("1 & 2", "unexpected \"&\"", 3),
    ("1 = 2", "unexpected \"=\"", 3),
    ("!1", "unexpected \"!\"", 1),
    ("2^^2", "unexpected \"^\"", 3),
    ("2***2", "unexpected \"*\"", 4),
    ("1 + $", "unexpected \"$\"", 5),
    ("é", "unexpected \"é\"", 1),
    ("1,2", "unexpected \",\"", 2),
    ("1 ]", "unexpected \"]\"", 3),
];

#[test]
fn errors() {
    let s = scope();
    for &(text, needle, column) in ERRORS {
        match evaluate(text, &s) {
            Ok(value) => {
                panic!("{text:?} evaluated to {value}, expected an error about {needle:?}")
            }
            Err(e) => {
                assert!(
                    e.message.contains(needle),
                    "{text:?}: {e} does not mention {needle:?}"
                );
                assert!(
                    e.message
                        .starts_with(&format!("cannot evaluate {text:?}: ")),
                    "{text:?}: {e}"
                );
                assert_eq!(e.column, column, "{text:?}: {e}");
                assert!(
                    e.to_string().ends_with(&format!(" at column {column}")),
                    "{e}"
                );
            }
        }
    }
}

#[test]
fn display() {
    let e = evaluate("2*(x+", &scope()).unwrap_err();
    assert_eq!(
        e.to_string(),
        "cannot evaluate \"2*(x+\": unexpected end at column 6"
    );
    let e = evaluate("foo+1", &scope()).unwrap_err();
    assert_eq!(
        e.to_string(),
        "cannot evaluate \"foo+1\": unknown name \"foo\" at column 1"
    );
}

#[test]
fn nesting_is_bounded() {
    let s = scope();
    let ok = format!(
        "{}1{}",
        "(".repeat(MAX_DEPTH - 1),
        ")".repeat(MAX_DEPTH - 1)
    );
    assert_eq!(evaluate(&ok, &s), Ok(1.0));
    let deep = format!("{}1{}", "(".repeat(10_000), ")".repeat(10_000));
    let e = evaluate(&deep, &s).unwrap_err();
    assert!(e.message.contains("nesting deeper than 256"), "{e}");
    assert_eq!(e.column, MAX_DEPTH + 1);
    assert!(
        e.message.len() < 400,
        "the message quotes a bounded part of the text"
    );
    for text in [
        "(".repeat(10_000),
        "sin(".repeat(10_000),
        "m[".repeat(10_000),
        format!("{}2", "2^".repeat(10_000)),
        format!("{}2", "-(".repeat(10_000)),
        format!("{}1", "1||(".repeat(10_000)),
    ] {
        let e = evaluate(&text, &s).unwrap_err();
        assert!(e.message.contains("nesting deeper"), "{e}");
    }
    // Signs and flat operator chains do not nest.
    assert_eq!(evaluate(&format!("{}1", "-".repeat(10_001)), &s), Ok(-1.0));
    let long = format!("{}1", "1+".repeat(100_000));
    assert_eq!(evaluate(&long, &s), Ok(100_001.0));
}

#[test]
fn deep_nesting_fits_a_small_stack() {
    // The deepest nesting allowed, through each recursive path, on a 1 MiB thread
    // (measured: about 90 KiB optimised, 400 KiB unoptimised).
    let depth = MAX_DEPTH - 1;
    let cases = [
        (format!("{}1{}", "(".repeat(depth), ")".repeat(depth)), 1.0),
        (
            format!("{}1{}", "sin(".repeat(depth), ")".repeat(depth)),
            (0..depth).fold(1.0, |x: f64, _| x.sin()),
        ),
        (
            format!("{}1{}", "v[".repeat(depth), "]/10".repeat(depth)),
            1.0,
        ),
        (format!("{}1", "1^".repeat(depth)), 1.0),
        // -(1 || ...) is -1, so every max(0, ...) is 0.
        (
            format!(
                "{}1{}",
                "max(0,-(1||2^(".repeat(depth / 4),
                ")))".repeat(depth / 4)
            ),
            0.0,
        ),
    ];
    let handle = std::thread::Builder::new()
        .stack_size(1024 * 1024)
        .spawn(move || {
            let s = scope();
            cases.map(|(text, expected)| (evaluate(&text, &s), expected, text))
        })
        .unwrap();
    for (result, expected, text) in handle.join().unwrap() {
        assert_eq!(result, Ok(expected), "{}...", &text[..20]);
    }
}

/// Evaluates and checks the invariants of any outcome.
fn check(text: &str, s: &dyn Scope) -> Result<f64, ExprError> {
    let result = evaluate(text, s);
    match &result {
        Ok(value) => assert!(value.is_finite(), "{text:?} gave {value}"),
        Err(e) => {
            assert!(e.column >= 1 && e.column <= text.len() + 1, "{text:?}: {e}");
            assert!(e.message.starts_with("cannot evaluate \""), "{text:?}: {e}");
        }
    }
    result
}

const VALID: &[&str] = &[
    "2*(HALFPI+0.2*PI)",
    "10*cm + 3*mm",
    "-2^2 + 2**3**2",
    "atan2(1, 1) * 4",
    "min(3, max(1, 2)) <= 2 && x > 1 || 0",
    "m[2, 3] + v[x - 1] * c_0 - m_1_2",
    "sqrt(x^2 + y^2) / (1 + exp(-y))",
    "fmod(floor(7.5), ceil(2.2)) + int(-1.7) + abs(-3) + fabs(-1e-3)",
    "(((1 + 2) * (3 - 4)) / 5.5e2) != 0",
    "log10(1000) + log(e) + sinh(0) + cosh(0) + tanh(0) + pow(2, -2)",
];

#[test]
fn fuzz_never_panics() {
    let s = scope();
    let mut rng = XorShift64(0x9E37_79B9_7F4A_7C15);
    for text in VALID {
        assert!(
            check(text, &s).is_ok(),
            "{text:?}: {:?}",
            evaluate(text, &s)
        );
    }
    // 10^5 random byte strings, made valid UTF-8.
    for _ in 0..100_000 {
        let len = rng.below(40);
        let bytes: Vec<u8> = (0..len).map(|_| rng.next_u64() as u8).collect();
        check(&String::from_utf8_lossy(&bytes), &s).ok();
    }
    // Random token soups.
    const TOKENS: &[&str] = &[
        "1", "2.5", ".5", "1e3", "1e", "1.", "e", "E", "pi", "x", "y", "zero", "huge", "bad", "m",
        "v", "c", "m_1_2", "v_0", "mm", "deg", "[", "]", ",", "(", ")", "+", "-", "*", "/", "^",
        "**", "==", "!=", "<", "<=", ">", ">=", "&&", "||", "|", "&", "=", "!", "sin(", "atan2(",
        "max(", "foo(", " ", "\t", ".", "_", "é", "\u{0}", "1e308", "0",
    ];
    for _ in 0..20_000 {
        let len = rng.below(24);
        let text: String = (0..len).map(|_| rng.pick(TOKENS)).collect();
        check(&text, &s).ok();
    }
    // Mutations of valid expressions.
    const INSERTS: &[&str] = &[
        "+", "-", "*", "/", "^", "(", ")", "[", "]", ",", " ", "1", "x", "((", "**", "e",
    ];
    for _ in 0..20_000 {
        let base = rng.pick(VALID);
        let mut text = base.to_string();
        for _ in 0..1 + rng.below(3) {
            let at = rng.below(text.len() + 1);
            match rng.below(4) {
                0 => text.truncate(at),
                1 => text.insert_str(at, rng.pick(INSERTS)),
                2 if at < text.len() => {
                    text.remove(at);
                }
                _ => {
                    let end = at + rng.below(text.len() - at + 1);
                    let piece = text[at..end].to_string();
                    text.insert_str(end, &piece);
                }
            }
        }
        check(&text, &s).ok();
    }
    // Every prefix of every valid expression.
    for text in VALID {
        for end in 0..=text.len() {
            check(&text[..end], &s).ok();
        }
    }
}

/// A random expression, fully parenthesised, with the value f64 arithmetic gives it
/// (`None` where the evaluator must refuse: division by zero, non-finite values).
fn random_expression(rng: &mut XorShift64, depth: usize) -> (String, Option<f64>) {
    const LITERALS: &[&str] = &[
        "0", "1", "2", "3", "7", "10", "0.5", "2.25", "0.125", "1e3", "1.5e-2", "100",
    ];
    if depth == 0 || rng.below(4) == 0 {
        let literal = rng.pick(LITERALS);
        return (literal.to_string(), Some(literal.parse().unwrap()));
    }
    let (a, va) = random_expression(rng, depth - 1);
    let (b, vb) = random_expression(rng, depth - 1);
    let finite = |v: f64| v.is_finite().then_some(v);
    let both = va.zip(vb);
    match rng.below(10) {
        0 => (format!("({a}+{b})"), both.and_then(|(x, y)| finite(x + y))),
        1 => (format!("({a}-{b})"), both.and_then(|(x, y)| finite(x - y))),
        2 => (format!("({a}*{b})"), both.and_then(|(x, y)| finite(x * y))),
        3 => (
            format!("({a}/{b})"),
            both.and_then(|(x, y)| if y == 0.0 { None } else { finite(x / y) }),
        ),
        4 => (format!("(-{a})"), va.map(|x| 0.0 - x)),
        5 => (
            format!("({a}^{b})"),
            both.and_then(|(x, y)| finite(x.powf(y))),
        ),
        6 => (
            format!("min({a},{b})"),
            both.map(|(x, y)| if x < y { x } else { y }),
        ),
        7 => (format!("atan2({a}, {b})"), both.map(|(x, y)| x.atan2(y))),
        8 => (format!("({a}<{b})"), both.map(|(x, y)| truth(x < y))),
        _ => (format!("sqrt({a})"), va.and_then(|x| finite(x.sqrt()))),
    }
}

#[test]
fn random_expressions_match_f64_arithmetic() {
    let mut rng = XorShift64(0x2545_F491_4F6C_DD1D);
    let (mut ok, mut refused) = (0, 0);
    for _ in 0..5000 {
        let (text, expected) = random_expression(&mut rng, 5);
        match (evaluate(&text, &()), expected) {
            (Ok(value), Some(expected)) => {
                assert_eq!(
                    value.to_bits(),
                    expected.to_bits(),
                    "{text}: {value} != {expected}"
                );
                ok += 1;
            }
            (Err(_), None) => refused += 1,
            (got, expected) => panic!("{text}: got {got:?}, expected {expected:?}"),
        }
    }
    assert!(ok > 1000 && refused > 50, "ok {ok}, refused {refused}");
}
