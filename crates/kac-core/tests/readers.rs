//! Readers on inputs written here for the features the shared files do not exercise, and fatal errors that
//! name the element, the rule and the line or byte offset.

use kac_core::geometry::validate::Facts;
use kac_core::geometry::Shape;
use kac_core::{load_bytes, Element, Format, Location, ReadOptions, ShapeError, ShapeKind, ValidateOptions, Validated};

fn ok(bytes: &[u8], f: Format) -> Validated {
    load_bytes(bytes, f, &ReadOptions::default(), &ValidateOptions::default()).unwrap_or_else(|e| panic!("{f}: {e}"))
}

fn err(bytes: &[u8], f: Format) -> ShapeError {
    match load_bytes(bytes, f, &ReadOptions::default(), &ValidateOptions::default()) {
        Ok(_) => panic!("{f}: expected an error"),
        Err(e) => e,
    }
}

fn tri(v: &Validated) -> &kac_core::geometry::TriangleMesh {
    match &v.shape {
        Shape::TriangleMesh(m) => m,
        _ => panic!("not a triangle mesh"),
    }
}

/// A unit square as two triangles, written in many ways.
const SQUARE_OBJ: &str = "# square\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvt 0.5 0.5\nvn 0 0 1\nf 1/1/1 2/2/1 3/3/1\nf -4/5/1 -2/4/1 -1/4/1\n";

#[test]
fn obj_corners_that_differ_only_in_uv_stay_one_vertex() {
    let v = ok(SQUARE_OBJ.as_bytes(), Format::Obj);
    let m = tri(&v);
    // Vertex 1 appears with uv 1 and uv 5: still one vertex, so the square is one connected piece.
    assert_eq!((m.vertices.len(), m.faces.len()), (4, 2));
    let Facts::Surface(f) = &v.report.facts else { panic!() };
    assert_eq!((f.components, f.boundary_loops, f.boundary_edges), (1, 1, 4));
    assert!((f.area - 1.0).abs() < 1e-15);
    assert!(v.map_is_identity());
}

#[test]
fn obj_lines_make_a_polyline_and_quads_are_split() {
    let v = ok(b"v 0 0 0\nv 1 0 0\nv 2 0 0\nv 3 1 0\nl 1 2 3 4 1\n", Format::Obj);
    assert_eq!(v.report.kind, ShapeKind::Polyline);
    let Facts::Curve(f) = &v.report.facts else { panic!() };
    assert_eq!((f.segments, f.components, f.closed_components), (4, 1, 1));
    let v = ok(b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n", Format::Obj);
    assert_eq!(tri(&v).faces.len(), 2);
    assert_eq!(v.report.repairs[0].code, "triangulated_polygons");
}

#[test]
fn nonconvex_polygon_is_ear_clipped_inside_its_outline() {
    // An L-shaped hexagon of area 3: a fan from vertex 0 would cover area outside it.
    let obj = b"v 0 0 0\nv 2 0 0\nv 2 1 0\nv 1 1 0\nv 1 2 0\nv 0 2 0\nf 1 2 3 4 5 6\n";
    let v = ok(obj, Format::Obj);
    let Facts::Surface(f) = &v.report.facts else { panic!() };
    assert_eq!(f.faces, 4);
    assert!((f.area - 3.0).abs() < 1e-12, "area {}", f.area);
    assert_eq!(f.orientation, kac_core::geometry::topology::Orientation::Consistent);
}

#[test]
fn off_variants_read() {
    let plain = ok(b"OFF\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n", Format::Off);
    // COFF with colours on vertices and faces, comments, counts on the header line.
    let coff = ok(b"COFF 4 2 0 # counts\n0 0 0 255 0 0 255\n1 0 0 0 255 0 255\n1 1 0 0 0 255 255\n0 1 0 9 9 9 255\n3 0 1 2 1 0 0\n3 0 2 3 0 1 0\n", Format::Off);
    // Homogeneous 4OFF: coordinates divided by w.
    let four = ok(b"4OFF\n4 2 0\n0 0 0 2\n2 0 0 2\n2 2 0 2\n0 2 0 2\n3 0 1 2\n3 0 2 3\n", Format::Off);
    assert_eq!(plain.id, coff.id);
    assert_eq!(plain.id, four.id);
}

#[test]
fn ply_big_endian_with_unusual_property_order_matches_ascii() {
    let ascii = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float z\nproperty uchar red\nproperty float x\nproperty float y\nelement face 1\nproperty uchar flags\nproperty list ushort uint vertex_indices\nend_header\n0 7 0 0\n0 7 1 0\n0 7 0 1\n3 3 0 1 2\n";
    let mut be = b"ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty float z\nproperty uchar red\nproperty float x\nproperty float y\nelement face 1\nproperty uchar flags\nproperty list ushort uint vertex_indices\nend_header\n".to_vec();
    for (x, y) in [(0f32, 0f32), (1.0, 0.0), (0.0, 1.0)] {
        be.extend_from_slice(&0f32.to_be_bytes());
        be.push(7);
        be.extend_from_slice(&x.to_be_bytes());
        be.extend_from_slice(&y.to_be_bytes());
    }
    be.push(3);
    be.extend_from_slice(&3u16.to_be_bytes());
    for i in 0u32..3 {
        be.extend_from_slice(&i.to_be_bytes());
    }
    let a = ok(ascii, Format::Ply);
    let b = ok(&be, Format::Ply);
    assert_eq!(tri(&a), tri(&b));
    assert_eq!(tri(&a).vertices[1], [1.0, 0.0, 0.0]);
}

#[test]
fn gmsh_v2_ascii_binary_and_v4_agree() {
    // One tetrahedron with node tags 10..13 and a boundary triangle element that is ignored beside tets.
    let v2 = b"$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n10 0 0 0\n11 1 0 0\n12 0 1 0\n13 0 0 1\n$EndNodes\n$Elements\n2\n1 2 2 0 1 10 11 12\n2 4 2 0 1 10 11 12 13\n$EndElements\n";
    let v4 = b"$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Entities\n0 0 0 1\n1 0 0 0 1 1 1 0 0\n$EndEntities\n$Nodes\n1 4 10 13\n3 1 0 4\n10\n11\n12\n13\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n$EndNodes\n$Elements\n1 1 1 1\n3 1 4 1\n1 10 11 12 13\n$EndElements\n";
    let mut bin = b"$MeshFormat\n2.2 1 8\n".to_vec();
    bin.extend_from_slice(&1i32.to_le_bytes());
    bin.extend_from_slice(b"\n$EndMeshFormat\n$Nodes\n4\n");
    for (tag, p) in [(10, [0.0, 0.0, 0.0]), (11, [1.0, 0.0, 0.0]), (12, [0.0, 1.0, 0.0]), (13, [0.0, 0.0, 1.0])] {
        bin.extend_from_slice(&i32::to_le_bytes(tag));
        for c in p {
            bin.extend_from_slice(&f64::to_le_bytes(c));
        }
    }
    bin.extend_from_slice(b"\n$EndNodes\n$Elements\n1\n");
    for x in [4i32, 1, 2, 1, 0, 1, 10, 11, 12, 13] {
        bin.extend_from_slice(&x.to_le_bytes());
    }
    bin.extend_from_slice(b"\n$EndElements\n");
    let a = ok(v2, Format::Gmsh);
    let b = ok(v4, Format::Gmsh);
    let c = ok(&bin, Format::Gmsh);
    assert_eq!(a.report.kind, ShapeKind::TetMesh);
    assert_eq!(a.id, b.id);
    assert_eq!(a.id, c.id);
    let Facts::Solid(f) = &a.report.facts else { panic!() };
    assert!((f.volume - 1.0 / 6.0).abs() < 1e-15);
}

#[test]
fn vtk_unstructured_grid_classic_and_5x_layouts() {
    let classic = b"# vtk DataFile Version 3.0\ntet\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 4 float\n0 0 0 1 0 0 0 1 0 0 0 1\nCELLS 1 5\n4 0 1 2 3\nCELL_TYPES 1\n10\nPOINT_DATA 4\nSCALARS s float 1\nLOOKUP_TABLE default\n1 2 3 4\n";
    let v5 = b"# vtk DataFile Version 5.1\ntet\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 4 float\n0 0 0 1 0 0 0 1 0 0 0 1\nCELLS 2 4\nOFFSETS vtktypeint64\n0 4\nCONNECTIVITY vtktypeint64\n0 1 2 3\nCELL_TYPES 1\n10\n";
    let a = ok(classic, Format::Vtk);
    let b = ok(v5, Format::Vtk);
    assert_eq!(a.report.kind, ShapeKind::TetMesh);
    assert_eq!(a.id, b.id);
    // POLYDATA quads that are flat stay a quad surface.
    let quads = b"# vtk DataFile Version 3.0\nq\nASCII\nDATASET POLYDATA\nPOINTS 4 float\n0 0 0 1 0 0 1 1 0 0 1 0\nPOLYGONS 1 5\n4 0 1 2 3\n";
    let q = ok(quads, Format::Vtk);
    assert_eq!(q.report.kind, ShapeKind::TriangleMesh);
}

#[test]
fn csv_xyz_and_json_inputs() {
    let csv = ok(b"x,y,z\n0,0,0\n1,0,0\n0,1,0\n", Format::Csv);
    assert_eq!(csv.report.kind, ShapeKind::PointCloud);
    assert_eq!(csv.shape.vertex_count(), 3);
    let planar = ok(b"0 0\n1 0\n0 1\n", Format::Xyz);
    assert!(planar.report.input.planar);
    assert_eq!(csv.id, planar.id, "2-D input is embedded at z = 0");
    // Weighted graph without positions: a triangle with a repeated edge merged.
    let g = ok(br#"{"vertex_count": 3, "edges": [[0,1],[1,2],[2,0],[1,0]], "weights": [1, 2, 3, 0.5]}"#, Format::Json);
    let Shape::Graph(graph) = &g.shape else { panic!() };
    assert_eq!(graph.edges.len(), 3);
    assert_eq!(graph.weights[0], 1.5);
    assert_eq!(g.report.repairs[0].code, "duplicate_edges");
    let mesh = ok(br#"{"vertices": [[0,0,0],[1,0,0],[0,1,0]], "faces": [[0,1,2]]}"#, Format::Json);
    assert_eq!(mesh.report.kind, ShapeKind::TriangleMesh);
}

/// Points in Rⁿ: 4 or more columns are coordinates (6 are a position and a normal unless a header names the
/// fourth column otherwise); rows that agree in their first three coordinates stay distinct points, exact
/// duplicates merge; the order of the rows does not change the id; .npy arrays read the same.
#[test]
fn points_in_rn_keep_every_coordinate() {
    let ambient = |v: &Validated| match &v.shape {
        Shape::PointCloud(c) => c.ambient.as_ref().map(|a| (a.dim, a.len())),
        _ => panic!("not a cloud"),
    };
    let four = ok(b"0,0,0,1\n0,0,0,-1\n1,0,0,0\n0,1,0,0\n0,1,0,0\n", Format::Csv);
    assert_eq!(ambient(&four), Some((4, 4)), "two rows share x, y, z but differ in w; one exact duplicate");
    assert_eq!(four.report.repairs[0].code, "duplicate_points");
    let shuffled = ok(b"0,1,0,0\n1,0,0,0\n0,0,0,-1\n0,0,0,1\n", Format::Csv);
    assert_eq!(four.id, shuffled.id);
    let six = ok(b"0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 0 0 1\n", Format::Xyz);
    assert_eq!(ambient(&six), None, "x y z nx ny nz");
    let Shape::PointCloud(c) = &six.shape else { panic!() };
    assert!(c.normals.is_some());
    let named = ok(b"a,b,c,d,e,f\n0,0,0,0,0,1\n1,0,0,0,0,1\n0,1,0,0,0,1\n", Format::Csv);
    assert_eq!(ambient(&named), Some((6, 3)), "a header naming the columns otherwise: points in R^6");
    let rows = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0];
    let npy = ok(&kac_core::io::npy::encode_f64(4, 4, &rows), Format::Npy);
    assert_eq!(npy.id, four.id);
    assert!(matches!(err(b"1\n2\n", Format::Xyz), ShapeError::Syntax { .. }));
}

#[test]
fn fatal_errors_name_the_element_rule_and_place() {
    match err(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 5\n", Format::Obj) {
        ShapeError::IndexOutOfRange {
            element: Element::Face,
            index: 0,
            value: 5,
            vertex_count: 3,
            location: Location::Line { line: 4 },
        } => {}
        e => panic!("{e:?}"),
    }
    match err(b"OFF\n3 1 0\n0 0 0\n1 nan 0\n0 1 0\n3 0 1 2\n", Format::Off) {
        ShapeError::NonFinite { element: Element::Vertex, index: 1, location: Location::Line { line: 4 }, .. } => {}
        e => panic!("{e:?}"),
    }
    match err(b"OFF\n3 1 0\n0 0 0\n1 0 0\n", Format::Off) {
        ShapeError::Truncated { .. } => {}
        e => panic!("{e:?}"),
    }
    match err(b"v 0 0 zero\n", Format::Obj) {
        ShapeError::Syntax { location: Location::Line { line: 1 }, message, .. } => assert!(message.contains("'zero'")),
        e => panic!("{e:?}"),
    }
    // A binary PLY whose face list runs past the end: a byte offset.
    let mut ply = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n".to_vec();
    let header = ply.len();
    ply.extend(std::iter::repeat_n(0u8, 36));
    ply.extend_from_slice(&[3, 0, 0, 0, 0]);
    match err(&ply, Format::Ply) {
        ShapeError::Truncated { location: Location::Byte { offset }, .. } => assert!(offset >= header + 36),
        e => panic!("{e:?}"),
    }
    match err(br#"{"vertices": [[0,0,0]], "faces": [[0,0,7]]}"#, Format::Json) {
        ShapeError::IndexOutOfRange { location: Location::Pointer { pointer }, .. } => {
            assert_eq!(pointer, "/faces/0/2")
        }
        e => panic!("{e:?}"),
    }
    match err(b"", Format::Obj) {
        ShapeError::Empty { .. } => {}
        e => panic!("{e:?}"),
    }
    match err(br#"{"vertex_count": 2, "edges": [[0,1]], "weights": [-1]}"#, Format::Json) {
        ShapeError::InvalidElement { element: Element::Edge, index: 0, .. } => {}
        e => panic!("{e:?}"),
    }
    // Every face degenerate: nothing usable is left, and the error says so.
    match err(b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", Format::Obj) {
        ShapeError::Empty { what } => assert!(what.contains("no usable triangle")),
        e => panic!("{e:?}"),
    }
}

#[test]
fn declared_counts_cannot_force_huge_allocations() {
    // A header that declares four billion vertices in a few bytes fails fast on the limit or the data.
    let e = err(b"ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\nproperty float x\nproperty float y\nproperty float z\nend_header\n", Format::Ply);
    assert!(matches!(e, ShapeError::LimitExceeded { .. } | ShapeError::Truncated { .. }), "{e:?}");
    let opts = ReadOptions { max_vertices: 2, ..Default::default() };
    let e = load_bytes(b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", Format::Off, &opts, &ValidateOptions::default())
        .unwrap_err();
    assert!(matches!(e, ShapeError::LimitExceeded { value: 3, limit: 2, .. }), "{e:?}");
}

#[test]
fn results_return_in_input_numbering() {
    // Vertex 1 is unreferenced and vertex 3 duplicates vertex 0.
    let v = ok(b"v 0 0 0\nv 9 9 9\nv 1 0 0\nv 0 0 0\nv 0 1 0\nf 1 3 5\nf 4 3 5\n", Format::Obj);
    assert_eq!(v.shape.vertex_count(), 3);
    let values: Vec<f64> = (0..3).map(|i| i as f64 * 10.0).collect();
    let back = v.to_input_numbering(&values, f64::NAN);
    assert_eq!(back.len(), 5);
    assert!(back[1].is_nan());
    assert_eq!(back[0], back[3]);
    let codes: Vec<&str> = v.report.repairs.iter().map(|r| r.code).collect();
    assert_eq!(codes, ["welded_vertices", "duplicate_faces", "unreferenced_vertices"]);
}

/// Bytes of one format read as another: the error names the format tried, what the bytes look like and how they
/// begin, instead of the wrong reader's complaint (OFF read as binary STL declared 856 million triangles).
#[test]
fn a_format_mismatch_names_both_formats() {
    use kac_core::io::{read_bytes, write, Format, ReadOptions};
    let mesh = kac_core::geometry::generate::icosphere(1);
    let off = write::off(&mesh).into_bytes();
    let ply = write::ply(&kac_core::Shape::TriangleMesh(mesh), true, None);
    for (bytes, tried, looks_like) in
        [(&off, Format::Stl, "off"), (&off, Format::Ply, "off"), (&ply, Format::Obj, "ply")]
    {
        match read_bytes(bytes, tried, &ReadOptions::default()) {
            Err(kac_core::ShapeError::FormatMismatch { tried: t, looks_like: l, head, reason }) => {
                assert_eq!((t, l), (tried.name(), looks_like));
                assert!(!reason.is_empty() && !head.is_empty());
                if looks_like == "off" {
                    assert!(head.starts_with("\"OFF"), "{head}");
                } else {
                    assert!(head.starts_with("\"ply"), "{head}");
                }
            }
            other => panic!("{tried:?}: {other:?}"),
        }
    }
    // Bytes of the format given keep the reader's own error.
    let err = read_bytes(b"OFF\n3 1 0\n0 0 0\n", Format::Off, &ReadOptions::default()).unwrap_err();
    assert!(matches!(err, kac_core::ShapeError::Truncated { .. }), "{err:?}");
}
