//! The hash-consed expression store. `intern` is the only way nodes enter the store; it never
//! simplifies (the simplifying constructors build on it).

use std::collections::HashMap;

use super::node::{ExprId, Node};

/// An append-only arena of unique nodes.
///
/// Invariants: every node appears once (`intern` of an equal node returns the existing id), and a
/// node's children have smaller ids than the node itself.
#[derive(Clone, Debug, Default)]
pub struct ExprStore {
    nodes: Vec<Node>,
    ids: HashMap<Node, ExprId>,
}

impl ExprStore {
    /// An empty store.
    pub fn new() -> Self {
        Self::default()
    }

    /// The id of `node`, adding it if it is new. Children must already be in this store.
    pub fn intern(&mut self, node: Node) -> ExprId {
        if let Some(&id) = self.ids.get(&node) {
            return id;
        }
        debug_assert!(node.children().all(|c| c.index() < self.nodes.len()));
        let id = ExprId(u32::try_from(self.nodes.len()).expect("expression store overflow"));
        self.nodes.push(node);
        self.ids.insert(node, id);
        id
    }

    /// The node `id` stands for.
    pub fn node(&self, id: ExprId) -> &Node {
        &self.nodes[id.index()]
    }

    /// The number of distinct nodes.
    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    /// Whether it holds no node.
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }
}
