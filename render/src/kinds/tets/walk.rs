//! The one traversal loop of the implicit BVH (tetrahedral-isosurface-ray-tracing.txt §5.2):
//! depth first from the root, the nearer child first. What a node costs, whether it is
//! entered and which rays go on below it is the walker's: one ray
//! ([`crate::kinds::tets::traverse`]) or a packet ([`crate::kinds::tets::packet`]).

use crate::kinds::tets::bvh::{Bvh, Node};

/// One traversal's decisions at each node.
pub(crate) trait Walker {
    /// What travels with a node on the stack: a ray's entry distance, a packet's first
    /// active ray.
    type Entry: Copy;
    /// Whether a popped node is visited, and with which entry.
    fn enter(&mut self, node: &Node, entry: Self::Entry) -> Option<Self::Entry>;
    /// Tests a leaf's tets; `true` ends the walk.
    fn leaf(&mut self, node: &Node, entry: Self::Entry) -> bool;
    /// The entries of an inner node's children `a` and `b` (`None`: culled), and whether `a`
    /// is visited first.
    fn children(
        &mut self,
        a: &Node,
        b: &Node,
        entry: Self::Entry,
    ) -> (Option<Self::Entry>, Option<Self::Entry>, bool);
}

/// Walks `bvh` from its root, whose entry is `root`.
#[inline]
pub(crate) fn walk<W: Walker>(bvh: &Bvh, root: W::Entry, walker: &mut W) {
    let nodes = &bvh.nodes;
    let mut stack = Stack::new((0u32, root));
    stack.push((0, root));
    while let Some((index, entry)) = stack.pop() {
        let node = &nodes[index as usize];
        let Some(entry) = walker.enter(node, entry) else {
            continue;
        };
        if node.is_leaf() {
            if walker.leaf(node, entry) {
                return;
            }
            continue;
        }
        let (a, b) = (node.first, node.first + 1);
        match walker.children(&nodes[a as usize], &nodes[b as usize], entry) {
            (Some(ea), Some(eb), a_first) => {
                if a_first {
                    stack.push((b, eb));
                    stack.push((a, ea));
                } else {
                    stack.push((a, ea));
                    stack.push((b, eb));
                }
            }
            (Some(ea), None, _) => stack.push((a, ea)),
            (None, Some(eb), _) => stack.push((b, eb)),
            (None, None, _) => {}
        }
    }
}

/// A traversal stack that lives on the call stack up to a depth of 64 and spills beyond.
pub(crate) struct Stack<T: Copy> {
    inline: [T; 64],
    len: usize,
    spill: Vec<T>,
}

impl<T: Copy> Stack<T> {
    pub(crate) fn new(fill: T) -> Stack<T> {
        Stack {
            inline: [fill; 64],
            len: 0,
            spill: Vec::new(),
        }
    }

    #[inline]
    pub(crate) fn push(&mut self, v: T) {
        if self.len < self.inline.len() {
            self.inline[self.len] = v;
            self.len += 1;
        } else {
            self.spill.push(v);
        }
    }

    #[inline]
    pub(crate) fn pop(&mut self) -> Option<T> {
        if let Some(v) = self.spill.pop() {
            return Some(v);
        }
        if self.len == 0 {
            return None;
        }
        self.len -= 1;
        Some(self.inline[self.len])
    }
}
