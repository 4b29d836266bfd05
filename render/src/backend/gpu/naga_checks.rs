//! What the GPU tests read of a kernel through naga (no device needed): the parsed module of
//! a kind's kernel, its constants, and a struct's size and member offsets against the
//! Rust twin's.

use crate::backend::gpu::kind::GpuKind;
use wgpu::naga;

/// The parsed kernel of `kind` (common.wgsl + the kind's part).
pub fn module_of(kind: GpuKind) -> naga::Module {
    let source = kind.kernel();
    naga::front::wgsl::parse_str(&source)
        .unwrap_or_else(|e| panic!("{}: {}", kind.name(), e.emit_to_string(&source)))
}

/// The literal the shader's constant `name` is initialised with.
fn literal(module: &naga::Module, name: &str) -> naga::Literal {
    let (_, c) = module
        .constants
        .iter()
        .find(|(_, c)| c.name.as_deref() == Some(name))
        .unwrap_or_else(|| panic!("constant {name} in the shader"));
    match module.global_expressions[c.init] {
        naga::Expression::Literal(l) => l,
        ref other => panic!("{name} = {other:?}"),
    }
}

/// The value of the shader's `u32` constant `name`.
pub fn constant(module: &naga::Module, name: &str) -> u32 {
    match literal(module, name) {
        naga::Literal::U32(v) => v,
        other => panic!("{name} = {other:?}, not a u32"),
    }
}

/// The value of the shader's `f32` constant `name`.
pub fn constant_f32(module: &naga::Module, name: &str) -> f32 {
    match literal(module, name) {
        naga::Literal::F32(v) => v,
        other => panic!("{name} = {other:?}, not an f32"),
    }
}

/// Asserts that the shader's struct `name` has `size` bytes and exactly the members
/// `offsets` (name, byte offset), in order: Rust's `size_of` and `offset_of!`.
pub fn same_layout(module: &naga::Module, name: &str, size: usize, offsets: &[(&str, usize)]) {
    let (_, ty) = module
        .types
        .iter()
        .find(|(_, t)| t.name.as_deref() == Some(name))
        .unwrap_or_else(|| panic!("struct {name} in the shader"));
    let naga::TypeInner::Struct { members, span } = &ty.inner else {
        panic!("{name} is not a struct: {:?}", ty.inner)
    };
    assert_eq!(*span as usize, size, "{name}: WGSL size vs Rust size");
    let wgsl: Vec<(&str, usize)> = members
        .iter()
        .map(|m| (m.name.as_deref().unwrap_or(""), m.offset as usize))
        .collect();
    assert_eq!(wgsl, offsets, "{name}: WGSL members vs Rust members");
}

/// `assert_layout!(module, "Name", RustType; field, ...)`: [`same_layout`] with the Rust
/// struct's size and each named field's offset.
macro_rules! assert_layout {
    ($m:expr, $name:expr, $t:ty; $($f:ident),* $(,)?) => {
        $crate::backend::gpu::naga_checks::same_layout(
            $m,
            $name,
            ::std::mem::size_of::<$t>(),
            &[$((stringify!($f), ::std::mem::offset_of!($t, $f))),*],
        )
    };
}
pub(crate) use assert_layout;
