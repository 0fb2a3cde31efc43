//! Dependency sorting of execution lists: every writer of a CSMat runs before the modules that
//! read it with a direct-feedthrough input.
//!
//! The sort is stable: among modules free to run, the one earlier in the list goes first, so a
//! list that is already in a valid order keeps it. Inputs read only in `state_update` add no
//! ordering constraint, which is what lets a controller with state close a loop. A module that
//! reads its own output is updating it in place and constrains nothing.

use std::cmp::Reverse;
use std::collections::{BinaryHeap, HashMap};
use std::fmt;

/// One module as the sort sees it.
#[derive(Clone, Debug, Default)]
pub struct SortNode<'a> {
    /// Module name (for errors).
    pub module: &'a str,
    /// CSMats it reads in `execute`.
    pub reads: Vec<&'a str>,
    /// CSMats it writes.
    pub writes: Vec<&'a str>,
}

/// Why a set of modules cannot be ordered.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum SortError {
    /// Two modules of the active set write the same CSMat.
    #[error("CSMat `{mat}` has two writers in the active set: `{first}` and `{second}`")]
    DoubleWriter {
        /// The CSMat.
        mat: String,
        /// One writer.
        first: String,
        /// The other.
        second: String,
    },
    /// A cycle through direct-feedthrough inputs only.
    #[error("algebraic loop through direct-feedthrough inputs: {}", Cycle(.modules, .mats))]
    AlgebraicLoop {
        /// The modules of the loop, each writing the next one's input.
        modules: Vec<String>,
        /// `mats[i]` is written by `modules[i]` and read by `modules[i + 1]` (cyclically).
        mats: Vec<String>,
    },
}

struct Cycle<'a>(&'a [String], &'a [String]);

impl fmt::Display for Cycle<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (module, mat) in self.0.iter().zip(self.1) {
            write!(f, "`{module}` -({mat})-> ")?;
        }
        match self.0.first() {
            Some(first) => write!(f, "`{first}`"),
            None => Ok(()),
        }
    }
}

/// The execution order of `nodes` (indices into it), or why there is none.
pub fn sort(nodes: &[SortNode<'_>]) -> Result<Vec<usize>, SortError> {
    let mut writer: HashMap<&str, usize> = HashMap::new();
    for (index, node) in nodes.iter().enumerate() {
        for &mat in &node.writes {
            if let Some(&first) = writer.get(mat) {
                if first != index {
                    return Err(SortError::DoubleWriter {
                        mat: mat.to_owned(),
                        first: nodes[first].module.to_owned(),
                        second: node.module.to_owned(),
                    });
                }
            } else {
                writer.insert(mat, index);
            }
        }
    }
    // preds[j]: (writer, mat) pairs j waits for.
    let mut preds: Vec<Vec<(usize, &str)>> = vec![Vec::new(); nodes.len()];
    let mut succs: Vec<Vec<usize>> = vec![Vec::new(); nodes.len()];
    for (index, node) in nodes.iter().enumerate() {
        for &mat in &node.reads {
            if let Some(&from) = writer.get(mat)
                && from != index
            {
                preds[index].push((from, mat));
                succs[from].push(index);
            }
        }
    }
    let mut waiting: Vec<usize> = preds.iter().map(Vec::len).collect();
    let mut ready: BinaryHeap<Reverse<usize>> = (0..nodes.len())
        .filter(|&index| waiting[index] == 0)
        .map(Reverse)
        .collect();
    let mut order = Vec::with_capacity(nodes.len());
    while let Some(Reverse(index)) = ready.pop() {
        order.push(index);
        for &next in &succs[index] {
            waiting[next] -= 1;
            if waiting[next] == 0 {
                ready.push(Reverse(next));
            }
        }
    }
    if order.len() == nodes.len() {
        return Ok(order);
    }
    Err(find_cycle(nodes, &preds, &waiting))
}

/// A cycle among the nodes left unsorted: each of them still waits for another one of them, so
/// walking back along unsatisfied inputs must revisit a node.
fn find_cycle(
    nodes: &[SortNode<'_>],
    preds: &[Vec<(usize, &str)>],
    waiting: &[usize],
) -> SortError {
    let start = waiting.iter().position(|&w| w > 0).unwrap_or(0);
    let mut seen: HashMap<usize, usize> = HashMap::new();
    let mut walk: Vec<(usize, &str)> = Vec::new(); // (node, mat it reads from the next entry)
    let mut at = start;
    loop {
        if let Some(&pos) = seen.get(&at) {
            // walk[pos..] is the cycle, in reader <- writer order: reverse it.
            let cycle = &walk[pos..];
            let mut modules: Vec<String> = Vec::with_capacity(cycle.len());
            let mut mats: Vec<String> = Vec::with_capacity(cycle.len());
            for &(node, _) in cycle.iter().rev() {
                modules.push(nodes[node].module.to_owned());
            }
            // cycle[k] reads cycle[k].1 from cycle[k + 1]; reversed, modules[i] = cycle[n-1-i]
            // writes the mat that modules[i + 1] = cycle[n-2-i] reads.
            let n = cycle.len();
            for i in 0..n {
                mats.push(cycle[(2 * n - 2 - i) % n].1.to_owned());
            }
            return SortError::AlgebraicLoop { modules, mats };
        }
        seen.insert(at, walk.len());
        let Some(&(from, mat)) = preds[at].iter().find(|(from, _)| waiting[*from] > 0) else {
            // Cannot happen for a node left unsorted; report what we have rather than panic.
            return SortError::AlgebraicLoop {
                modules: vec![nodes[at].module.to_owned()],
                mats: Vec::new(),
            };
        };
        walk.push((at, mat));
        at = from;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn node<'a>(module: &'a str, reads: &[&'a str], writes: &[&'a str]) -> SortNode<'a> {
        SortNode {
            module,
            reads: reads.to_vec(),
            writes: writes.to_vec(),
        }
    }

    fn names(nodes: &[SortNode<'_>], order: &[usize]) -> Vec<String> {
        order.iter().map(|&i| nodes[i].module.to_owned()).collect()
    }

    #[test]
    fn writers_come_before_readers_and_order_is_otherwise_kept() {
        let nodes = [
            node("ctrl", &["y"], &["u"]),
            node("log", &[], &[]),
            node("sensor", &["raw"], &["y"]),
            node("plant", &[], &["raw"]),
        ];
        let order = sort(&nodes).unwrap();
        assert_eq!(names(&nodes, &order), ["log", "plant", "sensor", "ctrl"]);
    }

    #[test]
    fn double_writer_names_both() {
        let nodes = [node("a", &[], &["u"]), node("b", &[], &["u"])];
        let err = sort(&nodes).unwrap_err();
        assert_eq!(
            err,
            SortError::DoubleWriter {
                mat: "u".into(),
                first: "a".into(),
                second: "b".into()
            }
        );
        assert!(err.to_string().contains("`a` and `b`"), "{err}");
    }

    #[test]
    fn algebraic_loop_names_modules_and_mats() {
        let nodes = [
            node("free", &[], &["z"]),
            node("a", &["c_out"], &["a_out"]),
            node("b", &["a_out"], &["b_out"]),
            node("c", &["b_out", "z"], &["c_out"]),
        ];
        let SortError::AlgebraicLoop { modules, mats } = sort(&nodes).unwrap_err() else {
            panic!("expected a loop")
        };
        assert_eq!(modules.len(), 3);
        let mut sorted = modules.clone();
        sorted.sort();
        assert_eq!(sorted, ["a", "b", "c"]);
        // mats[i] is written by modules[i] and read by modules[i+1].
        for (i, mat) in mats.iter().enumerate() {
            let writer = nodes.iter().find(|n| n.module == modules[i]).unwrap();
            let reader = nodes
                .iter()
                .find(|n| n.module == modules[(i + 1) % 3])
                .unwrap();
            assert!(
                writer.writes.contains(&mat.as_str()),
                "{modules:?} {mats:?}"
            );
            assert!(reader.reads.contains(&mat.as_str()), "{modules:?} {mats:?}");
        }
    }

    #[test]
    fn reading_own_output_is_not_a_loop() {
        let nodes = [
            node("integrator", &["x", "u"], &["x"]),
            node("src", &[], &["u"]),
        ];
        let order = sort(&nodes).unwrap();
        assert_eq!(names(&nodes, &order), ["src", "integrator"]);
    }

    /// A random DAG: module i writes `m{i}` and reads a random subset of earlier modules'
    /// outputs; the list is then shuffled.
    fn dag() -> impl Strategy<Value = (Vec<Vec<usize>>, Vec<usize>)> {
        (1usize..24).prop_flat_map(|n| {
            let reads = (0..n)
                .map(|i| proptest::collection::vec(0..i.max(1), 0..4.min(i + 1)))
                .collect::<Vec<_>>();
            (reads, Just((0..n).collect::<Vec<_>>()).prop_shuffle())
        })
    }

    proptest! {
        #[test]
        fn every_writer_precedes_its_readers((reads, perm) in dag()) {
            let mats: Vec<String> = (0..reads.len()).map(|i| format!("m{i}")).collect();
            let modules: Vec<String> = (0..reads.len()).map(|i| format!("mod{i}")).collect();
            let nodes: Vec<SortNode<'_>> = perm
                .iter()
                .map(|&i| SortNode {
                    module: &modules[i],
                    reads: reads[i].iter().filter(|&&r| r < i).map(|&r| mats[r].as_str()).collect(),
                    writes: vec![mats[i].as_str()],
                })
                .collect();
            let order = sort(&nodes).unwrap();
            prop_assert_eq!(order.len(), nodes.len());
            let mut position = vec![usize::MAX; nodes.len()];
            for (pos, &index) in order.iter().enumerate() {
                prop_assert_eq!(position[index], usize::MAX, "each module once");
                position[index] = pos;
            }
            for (j, reader) in nodes.iter().enumerate() {
                for mat in &reader.reads {
                    let w = nodes.iter().position(|n| n.writes.contains(mat)).unwrap();
                    prop_assert!(position[w] < position[j], "{} before {}", nodes[w].module, reader.module);
                }
            }
        }

        #[test]
        fn a_back_edge_makes_a_loop_that_is_reported((reads, perm) in dag(), pick in any::<prop::sample::Index>()) {
            // Close a loop: pick a reader j with some input r, and make r read j's output.
            let n = reads.len();
            let Some((j, r)) = (0..n)
                .flat_map(|j| reads[j].iter().filter(move |&&r| r < j).map(move |&r| (j, r)))
                .nth(pick.index(usize::MAX) % n.max(1)).or_else(|| {
                    (0..n).find_map(|j| reads[j].iter().find(|&&r| r < j).map(|&r| (j, r)))
                }) else { return Ok(()); };
            let mats: Vec<String> = (0..n).map(|i| format!("m{i}")).collect();
            let modules: Vec<String> = (0..n).map(|i| format!("mod{i}")).collect();
            let nodes: Vec<SortNode<'_>> = perm
                .iter()
                .map(|&i| {
                    let mut rd: Vec<&str> = reads[i].iter().filter(|&&x| x < i).map(|&x| mats[x].as_str()).collect();
                    if i == r { rd.push(mats[j].as_str()); }
                    SortNode { module: &modules[i], reads: rd, writes: vec![mats[i].as_str()] }
                })
                .collect();
            match sort(&nodes) {
                Err(SortError::AlgebraicLoop { modules: cyc, mats: via }) => {
                    prop_assert!(cyc.len() >= 2);
                    prop_assert_eq!(cyc.len(), via.len());
                    for (i, mat) in via.iter().enumerate() {
                        let w = nodes.iter().find(|x| x.module == cyc[i]).unwrap();
                        let rd = nodes.iter().find(|x| x.module == cyc[(i + 1) % cyc.len()]).unwrap();
                        prop_assert!(w.writes.contains(&mat.as_str()));
                        prop_assert!(rd.reads.contains(&mat.as_str()));
                    }
                }
                other => prop_assert!(false, "expected a loop, got {:?}", other),
            }
        }
    }
}
