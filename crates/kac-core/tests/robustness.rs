//! Property tests: random bytes and random mutations of valid files never panic any reader or the validator.
//! They either read (and validate to a shape or a typed error) or fail with a typed error.

mod common;

use kac_core::{load_bytes, Format, ReadOptions, ValidateOptions};
use proptest::prelude::*;

fn read_all_ways(bytes: &[u8]) {
    let opts = ReadOptions { max_vertices: 1 << 20, max_elements: 1 << 21 };
    for f in Format::ALL {
        let _ = load_bytes(bytes, f, &opts, &ValidateOptions::default());
    }
    let _ = Format::sniff(bytes);
}

/// Small valid inputs of every format, written here (the shared files are added when present).
fn seeds() -> Vec<Vec<u8>> {
    let mut s: Vec<Vec<u8>> = vec![
        b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2/1/1 4//1\nf -1 -2 -3 -4\nl 1 2 3\n".to_vec(),
        b"OFF\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n3 0 2 3\n".to_vec(),
        b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n".to_vec(),
        b"solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid t\n".to_vec(),
        b"MeshVersionFormatted 1\nDimension 3\nVertices\n4\n0 0 0 0\n1 0 0 0\n0 1 0 0\n0 0 1 0\nTetrahedra\n1\n1 2 3 4 0\nEnd\n".to_vec(),
        b"$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$EndNodes\n$Elements\n1\n1 4 2 0 1 1 2 3 4\n$EndElements\n".to_vec(),
        b"# vtk DataFile Version 3.0\nt\nASCII\nDATASET POLYDATA\nPOINTS 4 float\n0 0 0 1 0 0 0 1 0 0 0 1\nPOLYGONS 1 5\n4 0 1 2 3\n".to_vec(),
        br#"{"vertices": [[0,0,0],[1,0,0],[0,1,0]], "faces": [[0,1,2]], "edges": [[0,1]], "weights": [2]}"#.to_vec(),
        b"0 0 0 0 0 1\n1 0 0 0 0 1\n".to_vec(),
        b"%%MatrixMarket matrix coordinate real symmetric\n3 3 3\n2 1 1.5\n3 2 2\n3 1 0.5\n".to_vec(),
    ];
    let mut stl = vec![0u8; 80];
    stl.extend_from_slice(&1u32.to_le_bytes());
    stl.extend(std::iter::repeat_n(0u8, 12));
    for p in [[0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] {
        for c in p {
            stl.extend_from_slice(&c.to_le_bytes());
        }
    }
    stl.extend_from_slice(&[0, 0]);
    s.push(stl);
    if let Some(dir) = common::data_dir() {
        for rel in [
            "gltf/BoxInterleaved.glb",
            "gltf/Box_embedded.gltf",
            "ply/nut_binary.ply",
            "stl/Moon_binary.stl",
            "obj/cube_no_bottom.obj",
            "off/degtri_sliding.off",
        ] {
            if let Ok(b) = std::fs::read(dir.join(rel)) {
                s.push(b);
            }
        }
    }
    s
}

#[derive(Debug, Clone)]
enum Mutation {
    Flip(usize, u8),
    Insert(usize, Vec<u8>),
    Delete(usize, usize),
    Truncate(usize),
    Digit(usize, u8),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        (any::<usize>(), any::<u8>()).prop_map(|(i, b)| Mutation::Flip(i, b)),
        (any::<usize>(), prop::collection::vec(any::<u8>(), 1..8)).prop_map(|(i, b)| Mutation::Insert(i, b)),
        (any::<usize>(), 1usize..16).prop_map(|(i, n)| Mutation::Delete(i, n)),
        any::<usize>().prop_map(Mutation::Truncate),
        (any::<usize>(), prop::sample::select(b"-0123456789e.nan ".to_vec())).prop_map(|(i, b)| Mutation::Digit(i, b)),
    ]
}

fn apply(mut b: Vec<u8>, muts: &[Mutation]) -> Vec<u8> {
    for m in muts {
        let n = b.len().max(1);
        match m {
            Mutation::Flip(i, x) if !b.is_empty() => {
                let k = i % n;
                b[k] ^= x | 1;
            }
            Mutation::Digit(i, x) if !b.is_empty() => {
                let k = i % n;
                b[k] = *x;
            }
            Mutation::Insert(i, bytes) => {
                let k = i % (b.len() + 1);
                b.splice(k..k, bytes.iter().copied());
            }
            Mutation::Delete(i, len) if !b.is_empty() => {
                let k = i % n;
                let e = (k + len).min(b.len());
                b.drain(k..e);
            }
            Mutation::Truncate(i) => {
                let k = i % (b.len() + 1);
                b.truncate(k);
            }
            _ => {}
        }
    }
    b
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, failure_persistence: None, .. ProptestConfig::default() })]

    #[test]
    fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..512)) {
        read_all_ways(&bytes);
    }

    #[test]
    fn random_text_never_panics(s in "[-0-9a-zA-Z .#/\n\\[\\]{},:\"$]{0,400}") {
        read_all_ways(s.as_bytes());
    }

    #[test]
    fn mutated_valid_files_never_panic(seed in any::<prop::sample::Index>(), muts in prop::collection::vec(mutation(), 1..6)) {
        let seeds = seeds();
        let base = seeds[seed.index(seeds.len())].clone();
        read_all_ways(&apply(base, &muts));
    }
}
