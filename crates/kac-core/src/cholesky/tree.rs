//! Independent subtrees of a supernodal elimination tree, for the threads of one factorization or block solve.
//!
//! A supernode's pattern names the rows below its columns that its columns touch; the first of them lies in its
//! parent. Two supernodes neither of which is an ancestor of the other never touch each other's columns: the
//! forward solve and the left-looking factorization of one subtree read and write only that subtree's columns and
//! its ancestors' rows. So disjoint subtrees run side by side, and what lies above them (the *top*: every ancestor
//! of a subtree's root) runs after them on one thread (the factorization gives its dense blocks to every thread).
//!
//! faer numbers supernodes in a postorder of the tree, so a subtree is a contiguous range of supernodes (and of
//! columns and factor values) ending at its root. [`Split::new`] checks that, and declines a tree that is not so
//! numbered. The split is chosen greedily: the heaviest subtree is cut at its root (the root joins the top, its
//! children become subtrees) while that lowers the estimated time, the subtrees dealt to the workers heaviest first
//! (Graham's longest-processing-time rule), the top counted as sequential.

use faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky;

/// At most this many cuts: the top stays a thin layer of the tree, and a split costs microseconds.
const MAX_CUTS: usize = 256;

/// Disjoint subtrees of the supernodal tree dealt to workers, and the supernodes above them.
#[derive(Debug, Clone, PartialEq)]
pub struct Split {
    /// Per worker, its subtrees as ranges of supernodes `first..root + 1`.
    pub parts: Vec<Vec<(usize, usize)>>,
    /// The supernodes in no subtree, ascending (children before parents): ancestors of subtree roots.
    pub top: Vec<usize>,
    /// The estimated time with the split against one worker (weights summed: 1 is no gain).
    pub speedup: f64,
}

impl Split {
    /// The split of `sn`'s tree for `workers` threads, supernode s weighing `weight[s]` (the factor's values for a
    /// solve, the multiply-adds done while factoring it for a factorization); `None` for one worker, a tree not
    /// numbered in postorder, or a split that gains less than 10 %.
    pub fn new(sn: &SymbolicSupernodalCholesky<usize>, workers: usize, weight: &[f64]) -> Option<Split> {
        let ns = sn.n_supernodes();
        if workers < 2 || ns < 2 || weight.len() != ns {
            return None;
        }
        let (begin, end) = (sn.supernode_begin(), sn.supernode_end());
        let mut owner = vec![0usize; sn.nrows()];
        for s in 0..ns {
            owner[begin[s]..end[s]].fill(s);
        }
        // Parent: the supernode of the first pattern row (patterns are ascending); none for a root.
        let parent: Vec<Option<usize>> =
            (0..ns).map(|s| sn.supernode(s).pattern().first().map(|&r| owner[r])).collect();
        // Subtree sizes and weights, children before parents (a postorder has every parent after its children).
        let mut size = vec![1usize; ns];
        let mut heavy = weight.to_vec();
        let own = weight;
        let mut children: Vec<Vec<usize>> = vec![Vec::new(); ns];
        let mut roots = Vec::new();
        for s in 0..ns {
            match parent[s] {
                Some(p) if p > s => {
                    size[p] += size[s];
                    heavy[p] += heavy[s];
                    children[p].push(s);
                }
                Some(_) => return None,
                None => roots.push(s),
            }
        }
        // Postorder: each node's children, ascending, tile the range just below it.
        for s in 0..ns {
            let mut next = s + 1 - size[s];
            for &c in &children[s] {
                if c + 1 < size[c] || c + 1 - size[c] != next {
                    return None;
                }
                next = c + 1;
            }
            if next != s {
                return None;
            }
        }
        let total: f64 = own.iter().sum();
        if !(total > 0.0) {
            return None;
        }
        let deal = |pool: &[usize]| -> (f64, Vec<Vec<usize>>) {
            let mut order = pool.to_vec();
            order.sort_by(|&a, &b| heavy[b].total_cmp(&heavy[a]));
            let mut load = vec![0.0f64; workers];
            let mut parts = vec![Vec::new(); workers];
            for s in order {
                let w = (0..workers).min_by(|&a, &b| load[a].total_cmp(&load[b])).unwrap_or(0);
                load[w] += heavy[s];
                parts[w].push(s);
            }
            (load.iter().cloned().fold(0.0, f64::max), parts)
        };
        let mut pool = roots;
        let mut top_weight = 0.0;
        let mut top = Vec::new();
        let (mut best_time, mut best) = (f64::INFINITY, None);
        for _ in 0..=MAX_CUTS {
            let (makespan, parts) = deal(&pool);
            let time = makespan + top_weight;
            if time < best_time {
                best_time = time;
                best = Some((parts, top.clone()));
            }
            // Cut the heaviest subtree that has children.
            let Some(pos) = (0..pool.len())
                .filter(|&i| !children[pool[i]].is_empty())
                .max_by(|&a, &b| heavy[pool[a]].total_cmp(&heavy[pool[b]]))
            else {
                break;
            };
            let s = pool.swap_remove(pos);
            top_weight += own[s];
            top.push(s);
            pool.extend_from_slice(&children[s]);
        }
        let (parts, mut top) = best?;
        let speedup = total / best_time;
        if speedup < 1.1 {
            return None;
        }
        top.sort_unstable();
        let parts = parts
            .into_iter()
            .map(|roots| {
                let mut ranges: Vec<(usize, usize)> = roots.iter().map(|&r| (r + 1 - size[r], r + 1)).collect();
                ranges.sort_unstable();
                ranges
            })
            .collect();
        Some(Split { parts, top, speedup })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cholesky::factor::Symbolic;
    use crate::geometry::{generate, Shape};
    use crate::operators;
    use faer::sparse::linalg::cholesky::SymbolicCholeskyRaw;

    /// On a sphere's Laplacian the split covers every supernode exactly once, its subtrees are closed under
    /// descendants (no supernode's parent lies in another subtree), the top holds only ancestors of subtree roots,
    /// and two workers' loads come out within a few per cent of half the factor.
    #[test]
    fn split_covers_the_tree_with_closed_subtrees() {
        let pair = operators::build(&Shape::TriangleMesh(generate::icosphere(5)), &Default::default()).unwrap().pair;
        let sym = Symbolic::analyze(&pair.pattern).unwrap();
        let SymbolicCholeskyRaw::Supernodal(sn) = sym.inner.raw() else { panic!("supernodal analysis expected") };
        let ns = sn.n_supernodes();
        let (begin, end) = (sn.supernode_begin(), sn.supernode_end());
        let weight: Vec<f64> = (0..ns)
            .map(|s| {
                let (c, r) = (end[s] - begin[s], sn.supernode(s).pattern().len());
                (c * (c + 1) / 2 + c * r) as f64
            })
            .collect();
        let split = Split::new(sn, 2, &weight).expect("a sphere's tree splits");
        let mut seen = vec![0u8; ns];
        let mut part_of = vec![usize::MAX; ns];
        for (w, part) in split.parts.iter().enumerate() {
            for &(a, e) in part {
                for s in a..e {
                    seen[s] += 1;
                    part_of[s] = w;
                }
            }
        }
        for &s in &split.top {
            seen[s] += 1;
        }
        assert!(seen.iter().all(|&c| c == 1), "every supernode once");
        let owner = |r: usize| (0..ns).find(|&s| begin[s] <= r && r < end[s]).unwrap();
        for part in &split.parts {
            for &(a, e) in part {
                for s in a..e - 1 {
                    let p = owner(sn.supernode(s).pattern()[0]);
                    assert!(p > s && p < e, "supernode {s}'s parent {p} outside its subtree {a}..{e}");
                }
            }
        }
        let loads: Vec<f64> =
            split.parts.iter().map(|p| p.iter().flat_map(|&(a, e)| a..e).map(|s| weight[s]).sum()).collect();
        let total: f64 = weight.iter().sum();
        assert!(split.speedup > 1.5, "{split:?}");
        for l in loads {
            assert!(l > 0.3 * total && l < 0.55 * total, "load {l} of {total}");
        }
    }
}
