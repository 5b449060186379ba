use super::*;

/// A mesh to write: nodes with their tags, elements with their Gmsh type and node tags.
struct Mesh {
    nodes: Vec<(u64, [f64; 3])>,
    elements: Vec<(i32, Vec<u64>)>,
}

/// The unit cube as six tetrahedra around the diagonal from corner 0 to corner 6 (node tags 101..=108), with
/// one boundary triangle that is not used beside them.
fn cube() -> Mesh {
    let corners = [[0., 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.], [0., 0., 1.], [1., 0., 1.], [1., 1., 1.]];
    let mut nodes: Vec<(u64, [f64; 3])> = corners.iter().enumerate().map(|(i, &p)| (101 + i as u64, p)).collect();
    nodes.push((108, [0., 1., 1.]));
    let tets = [[0, 1, 2, 6], [0, 2, 3, 6], [0, 3, 7, 6], [0, 7, 4, 6], [0, 4, 5, 6], [0, 5, 1, 6]];
    let mut elements = vec![(2, vec![101, 102, 103])];
    elements.extend(tets.iter().map(|t| (4, t.iter().map(|&k| 101 + k as u64).collect())));
    Mesh { nodes, elements }
}

/// A unit square of two triangles and a boundary line, tags out of order.
fn square() -> Mesh {
    Mesh {
        nodes: vec![(7, [0., 0., 0.]), (3, [1., 0., 0.]), (9, [1., 1., 0.]), (4, [0.25, 1., 0.])],
        elements: vec![(2, vec![7, 3, 9]), (2, vec![7, 9, 4]), (1, vec![7, 3])],
    }
}

fn dim_of(ty: i32) -> i32 {
    match ty {
        4 => 3,
        2 => 2,
        1 => 1,
        _ => 0,
    }
}

/// What the reader should make of a mesh.
fn expected(mesh: &Mesh) -> RawShape {
    let index: HashMap<u64, u32> = mesh.nodes.iter().enumerate().map(|(i, n)| (n.0, i as u32)).collect();
    let mut raw = RawShape { vertices: mesh.nodes.iter().map(|n| n.1).collect(), ..RawShape::default() };
    let at = |tags: &[u64]| tags.iter().map(|t| index[t]).collect::<Vec<u32>>();
    let has_tets = mesh.elements.iter().any(|e| e.0 == 4);
    for (ty, tags) in &mesh.elements {
        let v = at(tags);
        match ty {
            4 => raw.tets.push([v[0], v[1], v[2], v[3]]),
            2 if !has_tets => raw.polygons.push(&v),
            1 => raw.segments.push([v[0], v[1]]),
            _ => {}
        }
    }
    raw
}

/// A section other than the mesh, written as Gmsh and solvers write it.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    PhysicalNames,
    Entities,
    PartitionedEntities,
    Periodic,
    GhostElements,
    Parametrizations,
    InterpolationScheme,
    NodeData,
    ElementData,
    ElementNodeData,
    Comments,
    Unknown,
}

const KINDS: [Kind; 12] = [
    Kind::PhysicalNames,
    Kind::Entities,
    Kind::PartitionedEntities,
    Kind::Periodic,
    Kind::GhostElements,
    Kind::Parametrizations,
    Kind::InterpolationScheme,
    Kind::NodeData,
    Kind::ElementData,
    Kind::ElementNodeData,
    Kind::Comments,
    Kind::Unknown,
];

impl Kind {
    fn name(self) -> &'static str {
        match self {
            Kind::PhysicalNames => "PhysicalNames",
            Kind::Entities => "Entities",
            Kind::PartitionedEntities => "PartitionedEntities",
            Kind::Periodic => "Periodic",
            Kind::GhostElements => "GhostElements",
            Kind::Parametrizations => "Parametrizations",
            Kind::InterpolationScheme => "InterpolationScheme",
            Kind::NodeData => "NodeData",
            Kind::ElementData => "ElementData",
            Kind::ElementNodeData => "ElementNodeData",
            Kind::Comments => "Comments",
            Kind::Unknown => "SolverAttributes",
        }
    }
    /// Sections of MSH 4 only.
    fn v4_only(self) -> bool {
        matches!(self, Kind::Entities | Kind::PartitionedEntities | Kind::GhostElements | Kind::Parametrizations)
    }
}

/// Where a section goes: before `$Nodes`, between `$Nodes` and `$Elements`, after `$Elements`.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Place {
    BeforeNodes,
    BeforeElements,
    AfterElements,
}

const PLACES: [Place; 3] = [Place::BeforeNodes, Place::BeforeElements, Place::AfterElements];

/// A file layout: version 2.2 or 4.1, ASCII or binary, byte order and (4.1 binary) `size_t` width.
#[derive(Clone, Copy, Debug)]
struct Msh {
    v4: bool,
    binary: bool,
    big: bool,
    word: usize,
}

const LAYOUTS: [Msh; 7] = [
    Msh { v4: false, binary: false, big: false, word: 8 },
    Msh { v4: false, binary: true, big: false, word: 8 },
    Msh { v4: false, binary: true, big: true, word: 8 },
    Msh { v4: true, binary: false, big: false, word: 8 },
    Msh { v4: true, binary: true, big: false, word: 8 },
    Msh { v4: true, binary: true, big: true, word: 8 },
    Msh { v4: true, binary: true, big: false, word: 4 },
];

/// `text` padded with spaces to `n` bytes: raw bytes where a binary file holds doubles, so that the
/// closing tag of the section appears inside its data.
fn spelled(text: &[u8], n: usize) -> Vec<u8> {
    let mut v = text.to_vec();
    v.resize(n, b' ');
    v
}

impl Msh {
    fn int(&self, o: &mut Vec<u8>, x: i32) {
        o.extend_from_slice(&if self.big { x.to_be_bytes() } else { x.to_le_bytes() });
    }
    fn f64(&self, o: &mut Vec<u8>, x: f64) {
        o.extend_from_slice(&if self.big { x.to_be_bytes() } else { x.to_le_bytes() });
    }
    fn size(&self, o: &mut Vec<u8>, x: u64) {
        match (self.word, self.big) {
            (4, true) => o.extend_from_slice(&(x as u32).to_be_bytes()),
            (4, false) => o.extend_from_slice(&(x as u32).to_le_bytes()),
            (_, true) => o.extend_from_slice(&x.to_be_bytes()),
            (_, false) => o.extend_from_slice(&x.to_le_bytes()),
        }
    }
    fn ints(&self, o: &mut Vec<u8>, xs: &[i32]) {
        xs.iter().for_each(|&x| self.int(o, x));
    }
    /// A 4.1 section of binary content: `ascii` in an ASCII file, `binary` written otherwise.
    fn counted(&self, o: &mut Vec<u8>, name: &str, ascii: &str, binary: impl FnOnce(&mut Vec<u8>)) {
        o.extend_from_slice(format!("${name}\n").as_bytes());
        if self.binary {
            binary(o);
            o.push(b'\n');
        } else {
            o.extend_from_slice(ascii.as_bytes());
        }
        o.extend_from_slice(format!("$End{name}\n").as_bytes());
    }

    fn write(&self, mesh: &Mesh, sections: &[(Place, Kind)]) -> Vec<u8> {
        let mut o =
            format!("$MeshFormat\n{} {} {}\n", if self.v4 { "4.1" } else { "2.2" }, self.binary as u8, self.word)
                .into_bytes();
        if self.binary {
            self.int(&mut o, 1);
            o.push(b'\n');
        }
        o.extend_from_slice(b"$EndMeshFormat\n");
        let put = |o: &mut Vec<u8>, place: Place| {
            for &(_, kind) in sections.iter().filter(|s| s.0 == place) {
                self.section(o, kind, mesh);
            }
        };
        put(&mut o, Place::BeforeNodes);
        if self.v4 {
            self.nodes_v4(&mut o, mesh);
        } else {
            self.nodes_v2(&mut o, mesh);
        }
        put(&mut o, Place::BeforeElements);
        if self.v4 {
            self.elements_v4(&mut o, mesh);
        } else {
            self.elements_v2(&mut o, mesh);
        }
        put(&mut o, Place::AfterElements);
        o
    }

    fn nodes_v2(&self, o: &mut Vec<u8>, mesh: &Mesh) {
        o.extend_from_slice(format!("$Nodes\n{}\n", mesh.nodes.len()).as_bytes());
        for &(tag, p) in &mesh.nodes {
            if self.binary {
                self.int(o, tag as i32);
                p.iter().for_each(|&c| self.f64(o, c));
            } else {
                o.extend_from_slice(format!("{tag} {} {} {}\n", p[0], p[1], p[2]).as_bytes());
            }
        }
        o.extend_from_slice(if self.binary { b"\n$EndNodes\n" } else { b"$EndNodes\n" });
    }

    fn elements_v2(&self, o: &mut Vec<u8>, mesh: &Mesh) {
        o.extend_from_slice(format!("$Elements\n{}\n", mesh.elements.len()).as_bytes());
        // Binary: one block per run of one type, each element with two tags (physical, elementary).
        let mut i = 0;
        while i < mesh.elements.len() {
            let ty = mesh.elements[i].0;
            let run = mesh.elements[i..].iter().take_while(|e| e.0 == ty).count();
            if self.binary {
                self.ints(o, &[ty, run as i32, 2]);
            }
            for (k, (_, tags)) in mesh.elements[i..i + run].iter().enumerate() {
                let id = (i + k + 1) as i32;
                if self.binary {
                    self.ints(o, &[id, 1, dim_of(ty)]);
                    tags.iter().for_each(|&t| self.int(o, t as i32));
                } else {
                    let nodes: Vec<String> = tags.iter().map(u64::to_string).collect();
                    o.extend_from_slice(format!("{id} {ty} 2 1 {} {}\n", dim_of(ty), nodes.join(" ")).as_bytes());
                }
            }
            i += run;
        }
        o.extend_from_slice(if self.binary { b"\n$EndElements\n" } else { b"$EndElements\n" });
    }

    /// Three blocks: the first node on a point, the next two on a surface with parametric (u, v), the
    /// rest in a volume.
    fn nodes_v4(&self, o: &mut Vec<u8>, mesh: &Mesh) {
        let n = mesh.nodes.len();
        let (min, max) = (mesh.nodes.iter().map(|x| x.0).min(), mesh.nodes.iter().map(|x| x.0).max());
        let (min, max) = (min.unwrap_or(0), max.unwrap_or(0));
        let blocks = [(0, 0..1, false), (2, 1..3, true), (3, 3..n, false)];
        o.extend_from_slice(b"$Nodes\n");
        if self.binary {
            [3, n as u64, min, max].iter().for_each(|&x| self.size(o, x));
        } else {
            o.extend_from_slice(format!("3 {n} {min} {max}\n").as_bytes());
        }
        for (dim, range, parametric) in blocks {
            let nodes = &mesh.nodes[range];
            if self.binary {
                self.ints(o, &[dim, 1, parametric as i32]);
                self.size(o, nodes.len() as u64);
                nodes.iter().for_each(|x| self.size(o, x.0));
                for (_, p) in nodes {
                    p.iter().for_each(|&c| self.f64(o, c));
                    if parametric {
                        self.f64(o, 0.5);
                        self.f64(o, 0.25);
                    }
                }
            } else {
                o.extend_from_slice(format!("{dim} 1 {} {}\n", parametric as u8, nodes.len()).as_bytes());
                nodes.iter().for_each(|x| o.extend_from_slice(format!("{}\n", x.0).as_bytes()));
                for (_, p) in nodes {
                    let uv = if parametric { " 0.5 0.25" } else { "" };
                    o.extend_from_slice(format!("{} {} {}{uv}\n", p[0], p[1], p[2]).as_bytes());
                }
            }
        }
        o.extend_from_slice(if self.binary { b"\n$EndNodes\n" } else { b"$EndNodes\n" });
    }

    /// One block per run of one type; element tags from 1.
    fn elements_v4(&self, o: &mut Vec<u8>, mesh: &Mesh) {
        let mut runs = Vec::new();
        let mut i = 0;
        while i < mesh.elements.len() {
            let run = mesh.elements[i..].iter().take_while(|e| e.0 == mesh.elements[i].0).count();
            runs.push(i..i + run);
            i += run;
        }
        let m = mesh.elements.len() as u64;
        o.extend_from_slice(b"$Elements\n");
        if self.binary {
            [runs.len() as u64, m, 1, m].iter().for_each(|&x| self.size(o, x));
        } else {
            o.extend_from_slice(format!("{} {m} 1 {m}\n", runs.len()).as_bytes());
        }
        for run in runs {
            let ty = mesh.elements[run.start].0;
            if self.binary {
                self.ints(o, &[dim_of(ty), 1, ty]);
                self.size(o, run.len() as u64);
            } else {
                o.extend_from_slice(format!("{} 1 {ty} {}\n", dim_of(ty), run.len()).as_bytes());
            }
            for k in run {
                let tags = &mesh.elements[k].1;
                if self.binary {
                    self.size(o, k as u64 + 1);
                    tags.iter().for_each(|&t| self.size(o, t));
                } else {
                    let nodes: Vec<String> = tags.iter().map(u64::to_string).collect();
                    o.extend_from_slice(format!("{} {}\n", k + 1, nodes.join(" ")).as_bytes());
                }
            }
        }
        o.extend_from_slice(if self.binary { b"\n$EndElements\n" } else { b"$EndElements\n" });
    }

    fn section(&self, o: &mut Vec<u8>, kind: Kind, mesh: &Mesh) {
        match kind {
            Kind::PhysicalNames => {
                o.extend_from_slice(b"$PhysicalNames\n2\n2 1 \"boundary\"\n3 2 \"solid body\"\n$EndPhysicalNames\n")
            }
            Kind::Comments => o.extend_from_slice(
                b"$Comments\nwritten by the kac tests; a line that looks like a section:\n$Nodes\n$EndComments\n",
            ),
            Kind::Unknown => {
                o.extend_from_slice(b"$SolverAttributes\nsolver = \"kac test\"\n$Elements\n$EndSolverAttributes\n")
            }
            Kind::InterpolationScheme => {
                o.extend_from_slice(b"$InterpolationScheme\n\"INTERPOLATION_SCHEME\"\n1\n5\n2\n4 4\n");
                for r in 0..4 {
                    let row: Vec<&str> = (0..4).map(|c| if r == c { "1" } else { "0" }).collect();
                    o.extend_from_slice(format!("{}\n", row.join(" ")).as_bytes());
                }
                o.extend_from_slice(b"4 3\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n$EndInterpolationScheme\n");
            }
            Kind::Periodic if !self.v4 => {
                o.extend_from_slice(b"$Periodic\n1\n0 1 2\n1\n101 102\n$EndPeriodic\n");
            }
            Kind::Periodic => self.counted(
                o,
                "Periodic",
                "1\n2 1 2\n16 1 0 0 1 0 1 0 0 0 0 1 0 0 0 0 1\n2\n101 105\n102 106\n",
                |o| {
                    self.size(o, 1);
                    self.ints(o, &[2, 1, 2]);
                    self.size(o, 16);
                    o.extend_from_slice(&spelled(b"\n$EndPeriodic\n", 16 * 8));
                    self.size(o, 2);
                    [101, 105, 102, 106].iter().for_each(|&t| self.size(o, t));
                },
            ),
            Kind::Entities => self.counted(
                o,
                "Entities",
                "1 1 1 1\n1 0 0 0 0\n1 0 0 0 1 1 1 1 7 2 1 -1\n1 0 0 0 1 1 1 1 1 1 1\n1 0 0 0 1 1 1 1 2 1 1\n",
                |o| {
                    [1, 1, 1, 1].iter().for_each(|&n| self.size(o, n));
                    self.int(o, 1);
                    [0., 0., 0.].iter().for_each(|&c| self.f64(o, c));
                    self.size(o, 0);
                    for dim in 1..4 {
                        self.int(o, 1);
                        o.extend_from_slice(&spelled(b"\n$EndEntities\n", 6 * 8));
                        self.size(o, 1);
                        self.int(o, 7);
                        self.size(o, 2);
                        self.ints(o, &[1, -dim]);
                    }
                },
            ),
            Kind::PartitionedEntities => self.counted(
                o,
                "PartitionedEntities",
                "2\n1\n5 2\n1 0 0 1\n3 0 1 1 1 0.5 0.5 0.5 0\n4 3 1 2 1 2 0 0 0 1 1 1 1 2 1 -3\n",
                |o| {
                    self.size(o, 2);
                    self.size(o, 1);
                    self.ints(o, &[5, 2]);
                    [1, 0, 0, 1].iter().for_each(|&n| self.size(o, n));
                    self.ints(o, &[3, 0, 1]);
                    self.size(o, 1);
                    self.int(o, 1);
                    [0.5, 0.5, 0.5].iter().for_each(|&c| self.f64(o, c));
                    self.size(o, 0);
                    self.ints(o, &[4, 3, 1]);
                    self.size(o, 2);
                    self.ints(o, &[1, 2]);
                    o.extend_from_slice(&spelled(b"\n$EndPartitionedEntities\n", 6 * 8));
                    self.size(o, 1);
                    self.int(o, 2);
                    self.size(o, 1);
                    self.int(o, -3);
                },
            ),
            Kind::GhostElements => self.counted(o, "GhostElements", "2\n1 1 1 2\n2 2 2 1 3\n", |o| {
                self.size(o, 2);
                self.size(o, 1);
                self.int(o, 1);
                self.size(o, 1);
                self.int(o, 2);
                self.size(o, 2);
                self.int(o, 2);
                self.size(o, 2);
                self.ints(o, &[1, 3]);
            }),
            Kind::Parametrizations => {
                let node = "0 0 0 0.5 0.5 1 0 0 0 1 0\n";
                let ascii = format!("1 1\n1 2\n0 0 0 0\n1 0 0 1\n2 3 1\n{node}{node}{node}0 1 2\n");
                self.counted(o, "Parametrizations", &ascii, |o| {
                    self.size(o, 1);
                    self.size(o, 1);
                    self.int(o, 1);
                    self.size(o, 2);
                    o.extend_from_slice(&spelled(b"\n$EndParametrizations\n", 2 * 4 * 8));
                    self.int(o, 2);
                    self.size(o, 3);
                    self.size(o, 1);
                    (0..33).for_each(|k| self.f64(o, k as f64));
                    self.ints(o, &[0, 1, 2]);
                });
            }
            Kind::NodeData | Kind::ElementData | Kind::ElementNodeData => self.data(o, kind, mesh),
        }
    }

    /// A view as Gmsh writes it: `$NodeData` a 3-vector per node, `$ElementData` a 3-vector per element,
    /// `$ElementNodeData` a scalar per node of each element. In binary, the first entity's values spell the
    /// closing tag.
    fn data(&self, o: &mut Vec<u8>, kind: Kind, mesh: &Mesh) {
        let name = kind.name();
        let (components, tags): (usize, Vec<(u64, usize)>) = match kind {
            Kind::NodeData => (3, mesh.nodes.iter().map(|n| (n.0, 1)).collect()),
            Kind::ElementData => (3, (1..=mesh.elements.len() as u64).map(|t| (t, 1)).collect()),
            _ => (1, mesh.elements.iter().enumerate().map(|(i, e)| (i as u64 + 1, e.1.len())).collect()),
        };
        o.extend_from_slice(
            format!(
                "${name}\n2\n\"velocity \\\"u\\\"\"\n\"INTERPOLATION_SCHEME\"\n1\n0.25\n4\n3\n{components}\n{}\n0\n",
                tags.len()
            )
            .as_bytes(),
        );
        let per_node = kind == Kind::ElementNodeData;
        for (k, &(tag, nodes)) in tags.iter().enumerate() {
            let n = components * nodes;
            if self.binary {
                self.int(o, tag as i32);
                if per_node {
                    self.int(o, nodes as i32);
                }
                let end = format!("\n$End{name}\n");
                if k == 0 && end.len() <= 8 * n {
                    o.extend_from_slice(&spelled(end.as_bytes(), 8 * n));
                } else {
                    (0..n).for_each(|j| self.f64(o, (k * 10 + j) as f64 * 0.5));
                }
            } else {
                let values: Vec<String> = (0..n).map(|j| ((k * 10 + j) as f64 * 0.5).to_string()).collect();
                let mult = if per_node { format!(" {nodes}") } else { String::new() };
                o.extend_from_slice(format!("{tag}{mult} {}\n", values.join(" ")).as_bytes());
            }
        }
        o.extend_from_slice(format!("{}$End{name}\n", if self.binary { "\n" } else { "" }).as_bytes());
    }
}

fn read_ok(bytes: &[u8], what: &str) -> RawShape {
    read(bytes, &ReadOptions::default()).unwrap_or_else(|e| panic!("{what}: {e}"))
}

fn same_mesh(raw: &RawShape, mesh: &Mesh, what: &str) {
    let want = expected(mesh);
    assert_eq!(raw.vertices, want.vertices, "{what}: vertices");
    assert_eq!(raw.tets, want.tets, "{what}: tetrahedra");
    assert_eq!(raw.polygons, want.polygons, "{what}: faces");
    assert_eq!(raw.segments, want.segments, "{what}: segments");
}

fn kinds_of(layout: Msh) -> impl Iterator<Item = Kind> {
    KINDS.into_iter().filter(move |k| layout.v4 || !k.v4_only())
}

#[test]
fn each_section_kind_is_skipped_before_nodes_before_and_after_elements_in_every_layout() {
    for layout in LAYOUTS {
        for (mesh_name, mesh) in [("cube", cube()), ("square", square())] {
            let plain = layout.write(&mesh, &[]);
            let raw = read_ok(&plain, &format!("{layout:?} {mesh_name}"));
            same_mesh(&raw, &mesh, &format!("{layout:?} {mesh_name}"));
            assert!(!raw.notes.iter().any(|n| n.contains("skipped")), "{:?}", raw.notes);
            for kind in kinds_of(layout) {
                for place in PLACES {
                    let what = format!("{layout:?} {mesh_name} {kind:?} {place:?}");
                    let bytes = layout.write(&mesh, &[(place, kind)]);
                    let raw = read_ok(&bytes, &what);
                    same_mesh(&raw, &mesh, &what);
                    let prefix = format!("gmsh: skipped ${} (1 ", kind.name());
                    let note = raw.notes.iter().find(|n| n.starts_with(&prefix));
                    let note = note.unwrap_or_else(|| panic!("{what}: no note in {:?}", raw.notes));
                    let searched = layout.binary && kind == Kind::Unknown;
                    assert_eq!(note.contains("searching for $EndSolverAttributes"), searched, "{what}: {note}");
                }
            }
        }
    }
}

#[test]
fn all_section_kinds_at_once_are_noted_once_per_kind_with_their_values() {
    let mesh = cube();
    for layout in LAYOUTS {
        let mut sections = Vec::new();
        for kind in kinds_of(layout) {
            sections.extend(PLACES.iter().map(|&p| (p, kind)));
        }
        let raw = read_ok(&layout.write(&mesh, &sections), &format!("{layout:?}"));
        same_mesh(&raw, &mesh, &format!("{layout:?}"));
        // 8 nodes × 3, 7 elements × 3, 1 triangle × 3 + 6 tets × 4 nodes; three views of each.
        for (name, values) in [("NodeData", 3 * 24), ("ElementData", 3 * 21), ("ElementNodeData", 3 * 27)] {
            let note = format!("gmsh: skipped ${name} (3 views, {values} values)");
            assert!(raw.notes.contains(&note), "{layout:?}: {note} not in {:?}", raw.notes);
        }
        for kind in
            kinds_of(layout).filter(|k| !matches!(k, Kind::NodeData | Kind::ElementData | Kind::ElementNodeData))
        {
            let prefix = format!("gmsh: skipped ${} (3 sections", kind.name());
            assert_eq!(
                raw.notes.iter().filter(|n| n.starts_with(&prefix)).count(),
                1,
                "{layout:?} {kind:?}: {:?}",
                raw.notes
            );
        }
        assert!(raw.notes.contains(&"gmsh: 1 surface element(s) beside the tetrahedra not used".to_string()));
    }
}

#[test]
fn binary_data_that_spells_its_closing_tag_is_skipped_by_its_declared_size() {
    let mesh = cube();
    for layout in LAYOUTS.into_iter().filter(|l| l.binary) {
        // The sections with doubles in binary (2.x `$Periodic` is text; `$GhostElements` holds no doubles).
        let with_doubles = |k: &Kind| match k {
            Kind::Periodic => layout.v4,
            k => !matches!(
                k,
                Kind::PhysicalNames | Kind::Comments | Kind::Unknown | Kind::InterpolationScheme | Kind::GhostElements
            ),
        };
        for kind in kinds_of(layout).filter(with_doubles) {
            let bytes = layout.write(&mesh, &[(Place::AfterElements, kind), (Place::BeforeNodes, kind)]);
            let tag = format!("\n$End{}\n", kind.name());
            let tags = bytes.windows(tag.len()).filter(|w| *w == tag.as_bytes()).count();
            assert!(tags >= 4, "{layout:?} {kind:?}: the closing tag is inside the data of each section");
            let raw = read_ok(&bytes, &format!("{layout:?} {kind:?}"));
            same_mesh(&raw, &mesh, &format!("{layout:?} {kind:?}"));
        }
    }
}

/// The bug: "section $ElementData is not closed" for a Gmsh 2.2 binary tet mesh with an `$ElementData` view.
/// Writers such as MshIO put the closing tags right after the binary data, with no newline, so no line of
/// the file is `$EndElementData`; Gmsh puts a newline first. Both are read.
#[test]
fn v22_binary_tet_mesh_with_element_data_is_read_not_refused_as_unclosed() {
    let mesh = cube();
    let layout = Msh { v4: false, binary: true, big: false, word: 8 };
    let gmsh = layout.write(&mesh, &[(Place::AfterElements, Kind::ElementData)]);
    let mut tight = gmsh.clone();
    for tag in [&b"\n$EndNodes"[..], b"\n$EndElements", b"\n$EndElementData"] {
        let at = tight.windows(tag.len()).rposition(|w| w == tag).unwrap_or_else(|| panic!("no closing tag"));
        tight.remove(at);
    }
    let end = tight.len() - b"$EndElementData\n".len();
    assert!(tight[end..] == b"$EndElementData\n"[..] && tight[end - 1] != b'\n');
    // And with the view's values free of the tag's bytes: then no line at all is `$EndElementData`.
    let mut plain = tight.clone();
    let spelled = b"\n$EndElementData\n";
    let at = plain.windows(spelled.len()).position(|w| w == spelled).unwrap_or_else(|| panic!("no spelled tag"));
    plain[at..at + spelled.len()].fill(0);
    assert!(!plain.split(|&c| c == b'\n').any(|l| l.trim_ascii() == b"$EndElementData"));
    for bytes in [gmsh, tight, plain] {
        let v = crate::load_bytes(&bytes, crate::Format::Gmsh, &ReadOptions::default(), &Default::default())
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(v.report.kind, crate::ShapeKind::TetMesh);
        assert_eq!(v.shape.vertex_count(), 8);
        let note = "gmsh: skipped $ElementData (1 view, 21 values)".to_string();
        assert!(v.report.notes.contains(&note), "{:?}", v.report.notes);
        same_mesh(&read_ok(&bytes, "v2.2 binary"), &mesh, "v2.2 binary");
    }
}

#[test]
fn declared_sizes_beyond_the_input_are_typed_errors_naming_the_section() {
    let v2 = Msh { v4: false, binary: true, big: false, word: 8 };
    let mut bytes = v2.write(&cube(), &[]);
    bytes.extend_from_slice(b"$ElementData\n1\n\"p\"\n1\n0\n3\n0\n1\n1000000\n");
    let at = bytes.len();
    bytes.extend_from_slice(&[0u8; 40]);
    bytes.extend_from_slice(b"\n$EndElementData\n");
    match read(&bytes, &ReadOptions::default()) {
        Err(ShapeError::Truncated { location, message, .. }) => {
            assert_eq!(location, Location::byte(at));
            assert!(message.contains("$ElementData"), "{message}");
        }
        other => panic!("{other:?}"),
    }
    // A 4.1 binary $Entities that declares more points than there are bytes.
    let v4 = Msh { v4: true, binary: true, big: false, word: 8 };
    let mut bytes = v4.write(&cube(), &[]);
    bytes.extend_from_slice(b"$Entities\n");
    [u64::MAX, 0, 0, 0].iter().for_each(|&n| v4.size(&mut bytes, n));
    bytes.extend_from_slice(b"\n$EndEntities\n");
    assert!(matches!(read(&bytes, &ReadOptions::default()), Err(ShapeError::Truncated { .. })));
    // 4.1 binary node and element counts past the input.
    let mut bytes = b"$MeshFormat\n4.1 1 8\n".to_vec();
    v4.int(&mut bytes, 1);
    bytes.extend_from_slice(b"\n$EndMeshFormat\n$Nodes\n");
    [1, 3, 1, 3].iter().for_each(|&n| v4.size(&mut bytes, n));
    v4.ints(&mut bytes, &[3, 1, 0]);
    v4.size(&mut bytes, 3);
    bytes.extend_from_slice(&[0u8; 30]);
    match read(&bytes, &ReadOptions::default()) {
        Err(ShapeError::Truncated { message, .. }) => assert!(message.contains("$Nodes"), "{message}"),
        other => panic!("{other:?}"),
    }
}

#[test]
fn data_that_disagrees_with_its_declared_size_is_an_error_at_its_place() {
    // Binary: one entity more than declared leaves bytes where $EndNodeData should be.
    let v2 = Msh { v4: false, binary: true, big: false, word: 8 };
    let mut bytes = v2.write(&square(), &[]);
    bytes.extend_from_slice(b"$NodeData\n0\n0\n3\n0\n1\n1\n");
    for tag in [7, 3] {
        v2.int(&mut bytes, tag);
        v2.f64(&mut bytes, 1.5);
    }
    let at = bytes.len() - 12;
    bytes.extend_from_slice(b"\n$EndNodeData\n");
    match read(&bytes, &ReadOptions::default()) {
        Err(ShapeError::Syntax { location, message, .. }) => {
            assert_eq!(location, Location::byte(at));
            assert!(message.contains("expected $EndNodeData"), "{message}");
        }
        other => panic!("{other:?}"),
    }
    // ASCII: fewer values than declared.
    let text =
        b"$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$NodeData\n1\n\"t\"\n0\n3\n0\n1\n3\n1 0.5\n2 0.5\n$EndNodeData\n";
    match read(text, &ReadOptions::default()) {
        Err(ShapeError::Syntax { location, message, .. }) => {
            assert_eq!(location, Location::line(14));
            assert!(message.contains("$NodeData"), "{message}");
        }
        other => panic!("{other:?}"),
    }
    // An unknown section of a binary file with no closing tag.
    let mut bytes = v2.write(&square(), &[]);
    let at = bytes.len();
    bytes.extend_from_slice(b"$Foo\n\x01\x02\n");
    match read(&bytes, &ReadOptions::default()) {
        Err(ShapeError::Truncated { location, message, .. }) => {
            assert_eq!(location, Location::byte(at));
            assert_eq!(message, "section $Foo is not closed");
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn every_prefix_of_a_binary_file_with_every_section_reads_or_fails_without_panic() {
    for layout in [LAYOUTS[1], LAYOUTS[5], LAYOUTS[6]] {
        let mut sections = Vec::new();
        for kind in kinds_of(layout) {
            sections.extend([(Place::BeforeNodes, kind), (Place::AfterElements, kind)]);
        }
        let bytes = layout.write(&cube(), &sections);
        for n in 0..bytes.len() {
            let _ = read(&bytes[..n], &ReadOptions::default());
        }
        // A flipped byte anywhere fails or reads, but never panics.
        for n in (0..bytes.len()).step_by(3) {
            let mut b = bytes.clone();
            b[n] ^= 0xA5;
            let _ = read(&b, &ReadOptions::default());
        }
    }
}

#[test]
fn many_kinds_of_unknown_sections_are_noted_up_to_a_bound() {
    let mut text = b"$MeshFormat\n2.2 0 8\n$EndMeshFormat\n".to_vec();
    for k in 0..20 {
        text.extend_from_slice(format!("$Extra{k}\nx\n$EndExtra{k}\n").as_bytes());
    }
    text.extend_from_slice(
        b"$Nodes\n3\n1 0 0 0\n2 1 0 0\n3 0 1 0\n$EndNodes\n$Elements\n1\n1 2 0 1 2 3\n$EndElements\n",
    );
    let raw = read_ok(&text, "20 unknown sections");
    assert_eq!(raw.polygons.len(), 1);
    assert_eq!(raw.notes.len(), NOTED_KINDS + 1);
    assert_eq!(raw.notes[0], "gmsh: skipped $Extra0 (1 section)");
    assert_eq!(raw.notes[NOTED_KINDS], "gmsh: skipped 4 more sections of other kinds");
}
