//! Which micro-kernel family runs: chosen once at runtime, overridable for tests.

use std::sync::OnceLock;

/// An instruction-set family with its own GEMM micro-kernel.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Isa {
    /// x86-64 AVX-512F: `avx512_sgemm_8x48`.
    Avx512,
    /// x86-64 AVX2 + FMA: `avx2_sgemm_6x16`.
    Avx2Fma,
    /// Plain Rust, auto-vectorised for the target's baseline: `portable_sgemm_4x16`.
    Portable,
}

impl Isa {
    /// Every family, fastest first.
    pub const ALL: [Isa; 3] = [Isa::Avx512, Isa::Avx2Fma, Isa::Portable];

    /// The fastest family this CPU supports (detected once). Setting the
    /// environment variable `PICKER_ISA` to `avx512`, `avx2` or `portable`
    /// caps it (never above what the CPU has).
    pub fn best() -> Isa {
        static BEST: OnceLock<Isa> = OnceLock::new();
        *BEST.get_or_init(|| {
            let cap = std::env::var("PICKER_ISA")
                .ok()
                .and_then(|s| Isa::parse(&s));
            Isa::ALL
                .into_iter()
                .filter(|isa| isa.is_available())
                .find(|isa| cap.is_none_or(|c| isa.rank() >= c.rank()))
                .unwrap_or(Isa::Portable)
        })
    }

    /// Parses `avx512`, `avx2` or `portable`.
    pub fn parse(s: &str) -> Option<Isa> {
        match s.trim().to_ascii_lowercase().as_str() {
            "avx512" | "avx512f" => Some(Isa::Avx512),
            "avx2" | "avx2fma" | "avx2+fma" => Some(Isa::Avx2Fma),
            "portable" | "generic" => Some(Isa::Portable),
            _ => None,
        }
    }

    /// Higher is slower/more portable.
    fn rank(self) -> u8 {
        match self {
            Isa::Avx512 => 0,
            Isa::Avx2Fma => 1,
            Isa::Portable => 2,
        }
    }

    /// True when this CPU can run the family.
    pub fn is_available(self) -> bool {
        match self {
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => std::arch::is_x86_feature_detected!("avx512f"),
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2Fma => {
                std::arch::is_x86_feature_detected!("avx2")
                    && std::arch::is_x86_feature_detected!("fma")
            }
            #[cfg(not(target_arch = "x86_64"))]
            Isa::Avx512 | Isa::Avx2Fma => false,
            Isa::Portable => true,
        }
    }

    /// Short name, as `PICKER_ISA` takes it.
    pub fn name(self) -> &'static str {
        match self {
            Isa::Avx512 => "avx512",
            Isa::Avx2Fma => "avx2",
            Isa::Portable => "portable",
        }
    }
}

impl std::fmt::Display for Isa {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Defines `fn name(isa: Isa, args…)` that runs the `#[inline(always)]`
/// function `body(args…)` compiled with the target features of `isa`'s
/// family (AVX-512F, AVX2 + FMA, or the baseline), so plain loops vectorise
/// for the widest registers. `isa` must be available on this CPU (the family
/// a layer was built for, or [`Isa::best`]). Exported for the other crates'
/// loops (`picker_tensor::per_isa!`); Rust never contracts `a * b + c` into
/// an FMA, so every family gives the same bits for the same operations.
#[macro_export]
macro_rules! per_isa {
    ($(#[$m:meta])* $vis:vis fn $name:ident $(<$lt:lifetime>)? ($($a:ident: $t:ty),* $(,)?) => $body:ident) => {
        $(#[$m])*
        $vis fn $name $(<$lt>)? (isa: $crate::Isa, $($a: $t),*) {
            #[cfg(target_arch = "x86_64")]
            #[target_feature(enable = "avx512f,avx2,fma")]
            unsafe fn avx512 $(<$lt>)? ($($a: $t),*) {
                $body($($a),*)
            }
            #[cfg(target_arch = "x86_64")]
            #[target_feature(enable = "avx2,fma")]
            unsafe fn avx2 $(<$lt>)? ($($a: $t),*) {
                $body($($a),*)
            }
            debug_assert!(isa.is_available());
            match isa {
                // SAFETY: the CPU has the family's features (see the macro's contract).
                #[cfg(target_arch = "x86_64")]
                $crate::Isa::Avx512 => unsafe { avx512($($a),*) },
                // SAFETY: as above.
                #[cfg(target_arch = "x86_64")]
                $crate::Isa::Avx2Fma => unsafe { avx2($($a),*) },
                _ => $body($($a),*),
            }
        }
    };
}
pub(crate) use crate::per_isa;

/// Bytes of the level-2 cache of one core, read once from Linux's sysfs
/// (`/sys/devices/system/cpu/cpu0/cache/index*/`); 1 MiB where it cannot be
/// read. Blocking choices that depend on it (the Winograd products' panel
/// groups) never change results, only speed.
pub(crate) fn l2_cache_bytes() -> usize {
    static L2: OnceLock<usize> = OnceLock::new();
    *L2.get_or_init(|| read_l2_bytes().unwrap_or(1 << 20))
}

/// The level-2 data or unified cache size from sysfs, if it is there.
fn read_l2_bytes() -> Option<usize> {
    let dir = std::path::Path::new("/sys/devices/system/cpu/cpu0/cache");
    for entry in std::fs::read_dir(dir).ok()?.flatten() {
        let read = |f: &str| std::fs::read_to_string(entry.path().join(f)).ok();
        if read("level")?.trim() != "2" || read("type")?.trim() == "Instruction" {
            continue;
        }
        return parse_cache_size(&read("size")?);
    }
    None
}

/// Parses sysfs cache sizes: `2048K`, `1M`, or plain bytes.
fn parse_cache_size(s: &str) -> Option<usize> {
    let s = s.trim();
    let (num, mul) = match s.as_bytes().last()? {
        b'K' | b'k' => (&s[..s.len() - 1], 1 << 10),
        b'M' | b'm' => (&s[..s.len() - 1], 1 << 20),
        _ => (s, 1),
    };
    num.parse::<usize>()
        .ok()
        .map(|n| n * mul)
        .filter(|&b| b > 0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cache_sizes_parse() {
        assert_eq!(parse_cache_size("2048K\n"), Some(2 << 20));
        assert_eq!(parse_cache_size("1M"), Some(1 << 20));
        assert_eq!(parse_cache_size("524288"), Some(1 << 19));
        assert_eq!(parse_cache_size("0K"), None);
        assert_eq!(parse_cache_size("big"), None);
        assert_eq!(parse_cache_size(""), None);
        assert!(l2_cache_bytes() > 0);
    }
}
