//! Generated shapes are what they claim: counts, closedness, orientation, area and volume.

use kac_core::geometry::generate::*;
use kac_core::geometry::validate::{validate, Facts};
use kac_core::geometry::{Polygons, RawShape};
use kac_core::ValidateOptions;

fn surface_facts(m: &kac_core::geometry::TriangleMesh) -> kac_core::geometry::topology::SurfaceFacts {
    let raw =
        RawShape { vertices: m.vertices.clone(), polygons: Polygons::from_triangles(&m.faces), ..Default::default() };
    let v = validate(raw, &ValidateOptions::default()).unwrap();
    assert!(v.report.repairs.is_empty(), "{:?}", v.report.repairs);
    match v.report.facts {
        Facts::Surface(f) => f,
        _ => panic!(),
    }
}

#[test]
fn icosphere_counts_and_geometry() {
    for (level, nv) in [(0, 12), (3, 642), (5, 10242)] {
        let m = icosphere(level);
        assert_eq!(m.vertices.len(), nv);
        assert_eq!(m.faces.len(), 20 * 4usize.pow(level));
        let f = surface_facts(&m);
        assert_eq!(
            (f.closed, f.genus, f.orientation),
            (true, Some(0), kac_core::geometry::topology::Orientation::Consistent)
        );
        // Inscribed polyhedron: area below 4π, approaching it.
        assert!(f.area < 4.0 * std::f64::consts::PI);
        if level == 5 {
            assert!((f.area - 4.0 * std::f64::consts::PI).abs() < 5e-3, "{}", f.area - 4.0 * std::f64::consts::PI);
        }
    }
}

#[test]
fn disk_square_torus_cube() {
    let d = surface_facts(&unit_disk(20));
    assert_eq!((d.boundary_loops, d.components, d.genus), (1, 1, Some(0)));
    // Inscribed 120-gon: area π·sin(2π/120)·120/(2π).
    let n = 120.0;
    assert!((d.area - 0.5 * n * (2.0 * std::f64::consts::PI / n).sin()).abs() < 1e-12);
    let s = surface_facts(&unit_square(8));
    assert!((s.area - 1.0).abs() < 1e-14);
    assert_eq!(s.boundary_edges, 32);
    let t = surface_facts(&torus(2.0, 0.5, 40, 20));
    assert_eq!((t.genus, t.closed), (Some(1), true));
    let c = unit_cube_tets(4);
    let raw = RawShape { vertices: c.vertices.clone(), tets: c.tets.clone(), ..Default::default() };
    let v = validate(raw, &ValidateOptions::default()).unwrap();
    let Facts::Solid(f) = v.report.facts else { panic!() };
    assert_eq!((f.inverted_tets, f.non_manifold_faces, f.boundary.genus), (0, 0, Some(0)));
    assert!((f.volume - 1.0).abs() < 1e-14 && (f.boundary.area - 6.0).abs() < 1e-14);
}
