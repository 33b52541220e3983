//! Command-line value types shared by several subcommands.

use clap::ValueEnum;
use picker_nets::{NetKind, StorageDtype};

/// A network name on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum NetArg {
    /// Intrinsic render-element network (six heads).
    Irn,
    /// Material segmentation network.
    Msn,
    /// Environment-map (lighting) network.
    Envmap,
    /// Learned texture inpainter (`picker extract --inpainter FILE`).
    Inpaint,
}

impl From<NetArg> for NetKind {
    fn from(n: NetArg) -> Self {
        match n {
            NetArg::Irn => NetKind::Irn,
            NetArg::Msn => NetKind::Msn,
            NetArg::Envmap => NetKind::EnvMap,
            NetArg::Inpaint => NetKind::Inpaint,
        }
    }
}

/// How float tensors are stored in a written weights file.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ValueEnum)]
pub enum DtypeArg {
    /// 32-bit float (exact).
    #[default]
    F32,
    /// IEEE half precision.
    F16,
    /// bfloat16.
    Bf16,
}

impl From<DtypeArg> for StorageDtype {
    fn from(d: DtypeArg) -> Self {
        match d {
            DtypeArg::F32 => StorageDtype::F32,
            DtypeArg::F16 => StorageDtype::F16,
            DtypeArg::Bf16 => StorageDtype::BF16,
        }
    }
}

/// Parses `HxW` (e.g. `240x320`: height 240, width 320), both positive.
pub fn parse_size(s: &str) -> Result<(usize, usize), String> {
    let bad = || format!("expected HEIGHTxWIDTH such as 240x320, got {s:?}");
    let (h, w) = s.split_once(['x', 'X', '×']).ok_or_else(bad)?;
    let h: usize = h.trim().parse().map_err(|_| bad())?;
    let w: usize = w.trim().parse().map_err(|_| bad())?;
    if h == 0 || w == 0 {
        return Err(format!("sizes must be positive, got {s:?}"));
    }
    Ok((h, w))
}

/// Most pixels one synthetic scene (`picker synth --size`) or one benchmark
/// input (`picker bench`, batch × height × width) may have, in megapixels: a
/// scene takes ~150 bytes a pixel while it is made (2.4 GB at this cap, per
/// thread), and the thesis IRN ~2.5 kB a pixel of activations; larger sizes
/// are refused up front instead of failing an allocation half-way.
pub const MAX_MEGAPIXELS: f64 = 16.0;

/// Refuses `pixels` above [`MAX_MEGAPIXELS`] as a usage error (exit
/// status 2), naming `what` (the options).
pub fn check_megapixels(what: &str, pixels: u64) -> anyhow::Result<()> {
    let mp = pixels as f64 / 1e6;
    if mp > MAX_MEGAPIXELS {
        return Err(anyhow::Error::new(crate::UsageError(format!(
            "{what}: {mp:.1} megapixels is more than the {MAX_MEGAPIXELS} this command accepts"
        ))));
    }
    Ok(())
}

/// `1234567` → `"1,234,567"`.
pub fn thousands(n: u64) -> String {
    let s = n.to_string();
    let mut out = String::with_capacity(s.len() + s.len() / 3);
    for (i, ch) in s.chars().enumerate() {
        if i > 0 && (s.len() - i).is_multiple_of(3) {
            out.push(',');
        }
        out.push(ch);
    }
    out
}

/// A parameter count for people: `108.86 M (108,856,080)`.
pub fn param_count(n: u64) -> String {
    let short = if n >= 1_000_000 {
        format!("{:.2} M", n as f64 / 1e6)
    } else if n >= 1_000 {
        format!("{:.2} K", n as f64 / 1e3)
    } else {
        n.to_string()
    };
    format!("{short} ({})", thousands(n))
}

/// A byte count for people, in decimal units: `435.4 MB`.
pub fn bytes(n: u64) -> String {
    let f = n as f64;
    if f >= 1e9 {
        format!("{:.2} GB", f / 1e9)
    } else if f >= 1e6 {
        format!("{:.1} MB", f / 1e6)
    } else if f >= 1e3 {
        format!("{:.1} kB", f / 1e3)
    } else {
        format!("{n} B")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats() {
        assert_eq!(thousands(108_856_080), "108,856,080");
        assert_eq!(thousands(999), "999");
        assert_eq!(thousands(1000), "1,000");
        assert_eq!(param_count(108_856_080), "108.86 M (108,856,080)");
        assert_eq!(param_count(812), "812 (812)");
        assert_eq!(bytes(435_424_320), "435.4 MB");
    }

    #[test]
    fn sizes() {
        assert_eq!(parse_size("240x320"), Ok((240, 320)));
        assert_eq!(parse_size("7X9"), Ok((7, 9)));
        assert!(parse_size("240").is_err());
        assert!(parse_size("0x5").is_err());
        assert!(parse_size("ax5").is_err());
    }
}
