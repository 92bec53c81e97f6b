//! A detector of 50 000 identical sensors imports as one solid and 50 000 transforms: its
//! Foundry stays under 10 MB, and every sensor is where its copy number says.

use hytrace_foundry::gdml::{parse_gdml, GdmlOptions};
use hytrace_tests::gdml::{synthetic_pmt_array, synthetic_pmt_direction};
use hytrace_trace::scan::{rays_from_rows, scan, Precision};
use hytrace_trace::scene::gdml_to_foundry;

const SENSORS: usize = 50_000;

#[test]
fn fifty_thousand_sensors_are_one_solid_and_fifty_thousand_instances() {
    let text = synthetic_pmt_array(SENSORS, false);
    let g = parse_gdml(&text, "pmt50k.gdml", &GdmlOptions::default()).unwrap();
    let f = gdml_to_foundry(&g).unwrap();
    assert_eq!(f.inst.len(), SENSORS + 1);
    assert_eq!(f.solid.len(), 2, "the world and the one sensor solid");
    let gpu: usize = f.gpu_array_bytes().iter().map(|b| b.len()).sum();
    let bytes = gpu + f.cpu_only_bytes();
    assert!(bytes < 10_000_000, "{bytes} bytes");
    // Rays from the centre towards sensors: each meets that sensor first (copy number i),
    // within the sensor's 130 mm reach of 20 m.
    let picks: Vec<usize> = (0..SENSORS).step_by(997).collect();
    let rows: Vec<[f64; 8]> = picks
        .iter()
        .map(|&i| {
            let d = synthetic_pmt_direction(i, SENSORS);
            [0.0, 0.0, 0.0, 0.0, d[0], d[1], d[2], f64::INFINITY]
        })
        .collect();
    let rays = rays_from_rows(&rows, "sensors").unwrap();
    let (hits, _) = scan(&f, &rays, Precision::F64).unwrap();
    for (k, &i) in picks.iter().enumerate() {
        let [instance, boundary, copy] = hits.ids[k];
        assert_eq!(copy, i as i32, "ray {k}: instance {instance}");
        assert!(boundary >= 0);
        let t = hits.hits[k][3];
        assert!(
            (20_000.0 - 130.0..=20_000.0 + 130.0).contains(&t),
            "ray {k}: t {t}"
        );
    }
}
