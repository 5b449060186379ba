//! Assembly time of the cotangent pair (L and consistent M) and of the other operators on unit icospheres
//! (the meshes bench/assembly.sh feeds the peers). Prints one JSON line per case; medians of 9 runs after a
//! warm-up. Threads: set RAYON_NUM_THREADS.

mod common;
use common::median;

use kac_core::geometry::{generate, Shape};
use kac_core::operators::{self, Mass, OperatorKind, OperatorOptions};
use std::time::Instant;

fn main() {
    let Some(levels) = common::levels(&[5, 6, 7]) else {
        return;
    };
    for level in levels {
        let shape = Shape::TriangleMesh(generate::icosphere(level));
        for (op, mass) in [
            (OperatorKind::Cotan, Mass::Consistent),
            (OperatorKind::Cotan, Mass::Lumped),
            (OperatorKind::IntrinsicDelaunay, Mass::Lumped),
            (OperatorKind::Robust, Mass::Lumped),
        ] {
            let o = OperatorOptions { operator: Some(op), mass: Some(mass), ..Default::default() };
            let _ = operators::build(&shape, &o).unwrap();
            let times: Vec<f64> = (0..9)
                .map(|_| {
                    let t = Instant::now();
                    let b = operators::build(&shape, &o).unwrap();
                    std::hint::black_box(&b);
                    t.elapsed().as_secs_f64()
                })
                .collect();
            println!(
                "{{\"vertices\": {}, \"operator\": \"{}\", \"mass\": \"{}\", \"threads\": {}, \"median_s\": {:.5}}}",
                shape.vertex_count(),
                op.name(),
                mass.name(),
                rayon::current_num_threads(),
                median(times)
            );
        }
    }
}
