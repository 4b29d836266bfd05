//! Which instruction-set extensions this build was compiled to use, and whether the running
//! CPU has them.
//!
//! The default build is portable (`x86-64`: SSE2). A build for newer CPUs
//! (`RUSTFLAGS="-C target-cpu=x86-64-v3"`: AVX2, FMA, BMI; README, "Building for the host CPU")
//! lets the compiler use 8-lane vectors in the loops it vectorises and VEX encodings
//! everywhere. Such a binary started on a CPU without them would die of an illegal
//! instruction somewhere in the first frame; [`missing`] lets `main` refuse to start instead,
//! naming what is missing. Images do not depend on the build: Rust does not contract `a * b + c`
//! into a fused multiply-add unless asked, so every build computes the same IEEE operations.

/// Each extension this module knows: its name, whether this build uses it, and whether the
/// running CPU has it (one list, so the two questions cannot drift apart).
fn extensions() -> Vec<(&'static str, bool, bool)> {
    #[allow(unused_mut)]
    let mut all: Vec<(&'static str, bool, bool)> = Vec::new();
    #[cfg(target_arch = "x86_64")]
    {
        macro_rules! each {
            ($($f:tt),*) => {$(
                all.push(($f, cfg!(target_feature = $f), std::arch::is_x86_feature_detected!($f)));
            )*};
        }
        each!(
            "sse3", "ssse3", "sse4.1", "sse4.2", "popcnt", "avx", "avx2", "fma", "bmi1", "bmi2",
            "lzcnt", "f16c", "movbe", "avx512f"
        );
    }
    all
}

/// The extensions beyond the portable baseline this binary was compiled to use.
pub fn compiled_for() -> Vec<&'static str> {
    let used = extensions().into_iter().filter(|&(_, used, _)| used);
    used.map(|(name, _, _)| name).collect()
}

/// Of [`compiled_for`], the extensions the running CPU lacks (empty when it can run this
/// binary).
pub fn missing() -> Vec<&'static str> {
    let lacking = extensions()
        .into_iter()
        .filter(|&(_, used, has)| used && !has);
    lacking.map(|(name, _, _)| name).collect()
}

/// One line for logs and benchmark headers: `portable x86-64` or the extensions in use.
pub fn build_line() -> String {
    let on = compiled_for();
    let wide = ["avx", "avx2", "fma", "avx512f"];
    if on.iter().any(|f| wide.contains(f)) {
        format!("built for {}", on.join(", "))
    } else {
        format!("portable build ({})", std::env::consts::ARCH)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_running_cpu_has_what_this_build_uses() {
        // The test binary is built like the engine: if it runs at all, nothing is missing;
        // and what is missing is always a subset of what the build uses.
        let (on, missing) = (compiled_for(), missing());
        assert!(missing.is_empty(), "{missing:?}");
        assert!(missing.iter().all(|f| on.contains(f)));
        // CI's build is the portable one: no extension listed, and the line says so.
        let wide = on
            .iter()
            .any(|f| ["avx", "avx2", "fma", "avx512f"].contains(f));
        assert_eq!(build_line().starts_with("portable build"), !wide, "{on:?}");
    }
}
