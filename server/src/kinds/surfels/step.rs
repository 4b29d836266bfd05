//! A surfel scene's steps: one row per simulation node, three columns (its position).

/// What the columns hold, for error messages.
pub const COLUMNS_HELP: &str =
    "a surfel step has 3 columns: each simulation node's position x y z, one row per node";

/// The name of column `col`.
pub fn column_name(col: usize) -> &'static str {
    ["x", "y", "z"].get(col).copied().unwrap_or("?")
}

/// Why a step of `rows` rows does not fit a scene of `nodes` simulation nodes, if it does not.
pub fn check_rows(nodes: u64, rows: u64) -> Option<String> {
    (rows != nodes).then(|| {
        format!("{rows} rows, but the scene has {nodes} simulation nodes: a surfel step has one position per node (a row beyond them names a node that does not exist)")
    })
}
