//! Every file of the shared test data reads, with the counts and properties its README lists (computed there
//! with independent readers: trimesh 5.2 and the authors' own). Counts "as stored" are compared with the
//! report's input counts; topology with validation set as the README's column says (welded or not).

mod common;

use kac_core::geometry::validate::{Facts, Weld};
use kac_core::{load, Format, ReadOptions, ShapeKind, ValidateOptions, Validated};

fn read(rel: &str, weld: Weld, drop_degenerate: bool) -> Option<Validated> {
    let dir = common::shared_data(rel);
    let opts = ValidateOptions { weld, drop_degenerate, kind: None };
    let (v, _) = load(&dir.join(rel), None, &ReadOptions::default(), &opts).unwrap_or_else(|e| panic!("{rel}: {e}"));
    Some(v)
}

struct Expect {
    file: &'static str,
    vertices: usize,
    faces: usize,
    components: usize,
    boundary_edges: usize,
    boundary_loops: usize,
    nm_edges: usize,
    nm_vertices: usize,
    genus: Option<i64>,
}

const SURFACES: &[Expect] = &[
    Expect {
        file: "obj/torus.obj",
        vertices: 2304,
        faces: 4608,
        components: 1,
        boundary_edges: 0,
        boundary_loops: 0,
        nm_edges: 0,
        nm_vertices: 0,
        genus: Some(1),
    },
    Expect {
        file: "obj/fish_low_resolution.obj",
        vertices: 945,
        faces: 1886,
        components: 1,
        boundary_edges: 0,
        boundary_loops: 0,
        nm_edges: 0,
        nm_vertices: 0,
        genus: Some(0),
    },
    Expect {
        file: "obj/cube_no_bottom.obj",
        vertices: 25,
        faces: 40,
        components: 1,
        boundary_edges: 8,
        boundary_loops: 1,
        nm_edges: 0,
        nm_vertices: 0,
        genus: Some(0),
    },
    Expect {
        file: "off/icosahedron.off",
        vertices: 12,
        faces: 20,
        components: 1,
        boundary_edges: 0,
        boundary_loops: 0,
        nm_edges: 0,
        nm_vertices: 0,
        genus: Some(0),
    },
    Expect {
        file: "off/torus.off",
        vertices: 576,
        faces: 1152,
        components: 1,
        boundary_edges: 0,
        boundary_loops: 0,
        nm_edges: 0,
        nm_vertices: 0,
        genus: Some(1),
    },
    Expect {
        file: "off/square-mesh.off",
        vertices: 415,
        faces: 768,
        components: 1,
        boundary_edges: 60,
        boundary_loops: 1,
        nm_edges: 0,
        nm_vertices: 0,
        genus: Some(0),
    },
    Expect {
        file: "off/eight.off",
        vertices: 315,
        faces: 634,
        components: 1,
        boundary_edges: 0,
        boundary_loops: 0,
        nm_edges: 0,
        nm_vertices: 0,
        genus: Some(2),
    },
    Expect {
        file: "off/mesh_with_border.off",
        vertices: 548,
        faces: 1014,
        components: 1,
        boundary_edges: 80,
        boundary_loops: 1,
        nm_edges: 0,
        nm_vertices: 0,
        genus: Some(0),
    },
    Expect {
        file: "ply/sphere_ascii.ply",
        vertices: 162,
        faces: 320,
        components: 1,
        boundary_edges: 0,
        boundary_loops: 0,
        nm_edges: 0,
        nm_vertices: 0,
        genus: Some(0),
    },
    Expect {
        file: "ply/airplane_ascii.ply",
        vertices: 1335,
        faces: 2452,
        components: 7,
        boundary_edges: 223,
        boundary_loops: 10,
        nm_edges: 1,
        nm_vertices: 6,
        genus: None,
    },
    Expect {
        file: "ply/nut_binary.ply",
        vertices: 523,
        faces: 1046,
        components: 1,
        boundary_edges: 0,
        boundary_loops: 0,
        nm_edges: 0,
        nm_vertices: 0,
        genus: Some(1),
    },
    Expect {
        file: "ply/sphere_binary.ply",
        vertices: 422,
        faces: 840,
        components: 1,
        boundary_edges: 0,
        boundary_loops: 0,
        nm_edges: 0,
        nm_vertices: 0,
        genus: Some(0),
    },
    Expect {
        file: "stl/HalfDonut_ascii.stl",
        vertices: 144,
        faces: 288,
        components: 1,
        boundary_edges: 0,
        boundary_loops: 0,
        nm_edges: 0,
        nm_vertices: 0,
        genus: Some(1),
    },
    Expect {
        file: "stl/HalfDonut_binary.stl",
        vertices: 144,
        faces: 288,
        components: 1,
        boundary_edges: 0,
        boundary_loops: 0,
        nm_edges: 0,
        nm_vertices: 0,
        genus: Some(1),
    },
    Expect {
        file: "stl/Moon_binary.stl",
        vertices: 60,
        faces: 116,
        components: 1,
        boundary_edges: 0,
        boundary_loops: 0,
        nm_edges: 0,
        nm_vertices: 0,
        genus: Some(0),
    },
    Expect {
        file: "stl/sphere_binary.stl",
        vertices: 162,
        faces: 320,
        components: 1,
        boundary_edges: 0,
        boundary_loops: 0,
        nm_edges: 0,
        nm_vertices: 0,
        genus: Some(0),
    },
    Expect {
        file: "stl/soup.stl",
        vertices: 300,
        faces: 100,
        components: 100,
        boundary_edges: 300,
        boundary_loops: 100,
        nm_edges: 0,
        nm_vertices: 0,
        genus: Some(0),
    },
    // glTF: the README counts split vertices, not welded.
    Expect {
        file: "gltf/Box_embedded.gltf",
        vertices: 24,
        faces: 12,
        components: 6,
        boundary_edges: 24,
        boundary_loops: 6,
        nm_edges: 0,
        nm_vertices: 0,
        genus: Some(0),
    },
    Expect {
        file: "gltf/BoxInterleaved.glb",
        vertices: 24,
        faces: 12,
        components: 6,
        boundary_edges: 24,
        boundary_loops: 6,
        nm_edges: 0,
        nm_vertices: 0,
        genus: Some(0),
    },
    Expect {
        file: "gltf/CesiumMilkTruck.glb",
        vertices: 3564,
        faces: 3624,
        components: 240,
        boundary_edges: 3082,
        boundary_loops: 267,
        nm_edges: 0,
        nm_vertices: 32,
        genus: None,
    },
    // Degenerate faces kept, as the README counts them.
    Expect {
        file: "off/degtri_sliding.off",
        vertices: 8,
        faces: 8,
        components: 1,
        boundary_edges: 6,
        boundary_loops: 1,
        nm_edges: 0,
        nm_vertices: 0,
        genus: Some(0),
    },
];

#[test]
#[ignore = "needs the shared meshes (KAC_TEST_DATA or ../shared/data): scripts/test-all.sh runs it with --ignored where they are"]
fn every_shared_surface_matches_its_readme_row() {
    for e in SURFACES {
        // STL is welded by its reader; glTF rows are counted unwelded; the rest are welded exactly, which
        // changes nothing for them.
        let weld = if e.file.starts_with("gltf/") { Weld::None } else { Weld::Exact };
        let Some(v) = read(e.file, weld, false) else { return };
        assert_eq!(v.report.kind, ShapeKind::TriangleMesh, "{}", e.file);
        let Facts::Surface(f) = &v.report.facts else { panic!("{}: not a surface", e.file) };
        let stored_vertices = if e.file.starts_with("stl/") { f.vertices } else { v.report.input.vertices };
        assert_eq!(stored_vertices, e.vertices, "{} vertices", e.file);
        assert_eq!(v.report.input.polygons, e.faces, "{} faces", e.file);
        assert_eq!(f.components, e.components, "{} components", e.file);
        assert_eq!(f.boundary_edges, e.boundary_edges, "{} boundary edges", e.file);
        assert_eq!(f.boundary_loops, e.boundary_loops, "{} boundary loops", e.file);
        assert_eq!(f.non_manifold_edges, e.nm_edges, "{} non-manifold edges", e.file);
        assert_eq!(f.non_manifold_vertices, e.nm_vertices, "{} non-manifold vertices", e.file);
        if e.genus.is_some() && e.components == 1 && e.boundary_edges == 0 {
            assert_eq!(f.genus, e.genus, "{} genus", e.file);
        }
        if e.nm_edges + e.nm_vertices > 0 {
            assert!(!f.manifold && v.report.warnings.iter().any(|w| w.contains("non-manifold")), "{}", e.file);
        }
    }
}

#[test]
#[ignore = "needs the shared meshes (KAC_TEST_DATA or ../shared/data): scripts/test-all.sh runs it with --ignored where they are"]
fn penguin_polygons_are_triangulated_and_recorded() {
    // 48 triangles, 169 quads and 4 pentagons: 48 + 2·169 + 3·4 = 398 triangles.
    let Some(v) = read("obj/penguin_control_mesh.obj", Weld::Exact, true) else { return };
    let Facts::Surface(f) = &v.report.facts else { panic!() };
    assert_eq!((f.vertices, f.faces), (201, 398));
    assert_eq!(v.report.input.non_triangle_polygons, 173);
    let r = v.report.repairs.iter().find(|r| r.code == "triangulated_polygons").expect("recorded");
    assert_eq!(r.count, 173);
    assert_eq!((f.genus, f.closed, f.manifold), (Some(0), true, true));
}

#[test]
#[ignore = "needs the shared meshes (KAC_TEST_DATA or ../shared/data): scripts/test-all.sh runs it with --ignored where they are"]
fn joined_tetrahedra_duplicate_face_is_dropped() {
    let Some(v) = read("obj/joined_tetrahedra.obj", Weld::Exact, true) else { return };
    let dup = v.report.repairs.iter().find(|r| r.code == "duplicate_faces").expect("recorded");
    assert_eq!(dup.count, 1);
    let Facts::Surface(f) = &v.report.facts else { panic!() };
    assert_eq!(f.faces, 7);
}

#[test]
#[ignore = "needs the shared meshes (KAC_TEST_DATA or ../shared/data): scripts/test-all.sh runs it with --ignored where they are"]
fn degenerate_triangles_are_found_and_dropped_by_default() {
    let Some(v) = read("off/degtri_sliding.off", Weld::Exact, true) else { return };
    let z = v.report.repairs.iter().find(|r| r.code == "zero_area_faces").expect("recorded");
    assert_eq!(z.count, 4);
    assert_eq!(z.examples.len(), 4);
}

#[test]
#[ignore = "needs the shared meshes (KAC_TEST_DATA or ../shared/data): scripts/test-all.sh runs it with --ignored where they are"]
fn gltf_split_vertices_weld_into_a_closed_cube() {
    for file in ["gltf/Box_embedded.gltf", "gltf/BoxInterleaved.glb"] {
        let Some(v) = read(file, Weld::Exact, true) else { return };
        let Facts::Surface(f) = &v.report.facts else { panic!() };
        assert_eq!((f.vertices, f.faces, f.components, f.closed, f.genus), (8, 12, 1, true, Some(0)), "{file}");
        // The Khronos box is the unit cube: area 6 and volume 1 after the node matrix.
        assert!((f.area - 6.0).abs() < 1e-6, "{file} area {}", f.area);
        assert!((f.enclosed_volume.unwrap() - 1.0).abs() < 1e-6, "{file}");
        assert!(!v.map_is_identity());
        // Every input vertex maps to one of the 8 cube corners at its own position.
        assert_eq!(v.vertex_map.len(), 24);
    }
}

#[test]
#[ignore = "needs the shared meshes (KAC_TEST_DATA or ../shared/data): scripts/test-all.sh runs it with --ignored where they are"]
fn tricky_binary_stl_with_solid_header_and_trailing_byte() {
    let dir = common::shared_data("stl");
    let bytes = std::fs::read(dir.join("stl/HalfDonut_binary.stl")).unwrap();
    assert!(bytes.starts_with(b"solid"));
    assert_eq!(Format::sniff(&bytes), Some(Format::Stl));
    let raw = kac_core::io::read_bytes(&bytes, Format::Stl, &ReadOptions::default()).unwrap();
    assert_eq!(raw.polygons.len(), 288);
    assert!(raw.notes.iter().any(|n| n.contains("1 trailing byte")));
}

#[test]
#[ignore = "needs the shared meshes (KAC_TEST_DATA or ../shared/data): scripts/test-all.sh runs it with --ignored where they are"]
fn tet_meshes_match_their_readme_rows() {
    let Some(v) = read("tet/cubeTetra.vtk", Weld::Exact, true) else { return };
    let Facts::Solid(f) = &v.report.facts else { panic!("cubeTetra is a solid") };
    assert_eq!((f.vertices, f.tets, f.inverted_tets, f.non_manifold_faces), (9261, 48000, 24000, 0));
    assert_eq!(
        (f.boundary.faces, f.boundary.vertices, f.boundary.closed, f.boundary.genus),
        (4800, 2402, true, Some(0))
    );
    // The unit cube: volume 1, boundary area 6.
    assert!((f.volume - 1.0).abs() < 1e-9 && (f.boundary.area - 6.0).abs() < 1e-9);
    assert!(v.report.notes.iter().any(|n| n.contains("lapy")));

    let Some(v) = read("tet/octopus-low.mesh", Weld::Exact, true) else { return };
    let Facts::Solid(f) = &v.report.facts else { panic!() };
    assert_eq!((f.vertices, f.tets, f.inverted_tets, f.non_manifold_faces), (452, 1140, 0, 0));
    assert_eq!(
        (f.boundary.faces, f.boundary.vertices, f.boundary.closed, f.boundary.manifold, f.boundary.genus),
        (898, 451, true, true, Some(0))
    );
}

#[test]
#[ignore = "needs the shared meshes (KAC_TEST_DATA or ../shared/data): scripts/test-all.sh runs it with --ignored where they are"]
fn point_clouds_read() {
    let Some(v) = read("points/kitten.xyz", Weld::Exact, true) else { return };
    assert_eq!(v.report.kind, ShapeKind::PointCloud);
    let Facts::Cloud(f) = &v.report.facts else { panic!() };
    assert_eq!((f.points, f.has_normals), (5210, true));
    let Some(v) = read("points/hippo1.ply", Weld::Exact, true) else { return };
    let Facts::Cloud(f) = &v.report.facts else { panic!() };
    assert_eq!(f.points, 6104);
}

#[test]
#[ignore = "needs the shared meshes (KAC_TEST_DATA or ../shared/data): scripts/test-all.sh runs it with --ignored where they are"]
fn the_same_mesh_in_two_formats_has_one_id() {
    let (Some(a), Some(b)) =
        (read("ply/sphere_ascii.ply", Weld::Exact, true), read("stl/sphere_binary.stl", Weld::Exact, true))
    else {
        return;
    };
    assert_eq!(a.id, b.id, "PLY (decimal text) and binary STL (f32) of the CGAL sphere");
    let (Some(a), Some(b)) =
        (read("stl/HalfDonut_ascii.stl", Weld::Exact, true), read("stl/HalfDonut_binary.stl", Weld::Exact, true))
    else {
        return;
    };
    assert_eq!(a.id, b.id);
    // Different shapes differ.
    let Some(c) = read("off/icosahedron.off", Weld::Exact, true) else { return };
    assert_ne!(a.id, c.id);
}

#[test]
#[ignore = "needs the shared meshes (KAC_TEST_DATA or ../shared/data): scripts/test-all.sh runs it with --ignored where they are"]
fn every_shared_file_reads_by_sniffing_alone() {
    let dir = common::shared_data("sniffing");
    for rel in [
        "obj/torus.obj",
        "off/eight.off",
        "ply/nut_binary.ply",
        "ply/airplane_ascii.ply",
        "stl/Moon_binary.stl",
        "stl/HalfDonut_ascii.stl",
        "gltf/Box_embedded.gltf",
        "gltf/CesiumMilkTruck.glb",
        "tet/octopus-low.mesh",
        "tet/cubeTetra.vtk",
        "points/kitten.xyz",
    ] {
        let bytes = std::fs::read(dir.join(rel)).unwrap();
        let f = Format::sniff(&bytes).unwrap_or_else(|| panic!("{rel}: not sniffed"));
        let by_ext = Format::from_name(rel.rsplit('.').next().unwrap()).unwrap();
        let same =
            f == by_ext || (f == Format::Gltf && by_ext == Format::Glb) || (f == Format::Glb && by_ext == Format::Gltf);
        assert!(same, "{rel}: sniffed {f}, extension says {by_ext}");
        kac_core::load_bytes(&bytes, f, &ReadOptions::default(), &ValidateOptions::default())
            .unwrap_or_else(|e| panic!("{rel}: {e}"));
    }
}
