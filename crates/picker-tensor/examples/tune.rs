//! Times one layer shape of the thesis networks at 240×320, for quick tuning
//! without criterion: `cargo run --release -p picker-tensor --example tune -- res`
//! (`TUNE_RUNS` sets the number of timed runs, default 49; `res`, `resmany`, `envres`, `envresmany`, `shape` (with `TUNE_SHAPE`), `decout`, `encin`, `down0`, `down1`, `envin`, `envdown0`, `envdown1`, `up0`, `up1`, `head` / `envhead` (the input conv and `down0` fused in bands; `head-unfused` / `envhead-unfused` one after the other), `dectail` (`up1` and `decout` fused in bands), `dectail-unfused`; `RAYON_NUM_THREADS`, `PICKER_ISA` apply).

use picker_tensor::{
    Activation, Conv2d, ConvAlgorithm, ConvSpec, ConvTranspose2d, ConvTransposeSpec, Isa, Rng,
    Tensor,
};
use std::time::Instant;

/// Runs `f` 49 times (`TUNE_RUNS` to change, e.g. longer for `perf record`)
/// and prints the median and minimum with their FLOP rates.
fn time_it(name: &str, flops: u64, mut f: impl FnMut() -> Tensor) {
    let runs = std::env::var("TUNE_RUNS")
        .ok()
        .and_then(|v| v.parse::<usize>().ok())
        .filter(|&n| n > 0)
        .unwrap_or(49);
    let mut t: Vec<f64> = (0..runs)
        .map(|_| {
            let t0 = Instant::now();
            std::hint::black_box(f());
            t0.elapsed().as_secs_f64()
        })
        .collect();
    t.sort_by(f64::total_cmp);
    let g = |s: f64| flops as f64 / s / 1e9;
    println!(
        "{name}: median {:.2} ms ({:.0} GFLOP/s), min {:.2} ms ({:.0} GFLOP/s)",
        t[runs / 2] * 1e3,
        g(t[runs / 2]),
        t[0] * 1e3,
        g(t[0])
    );
}

fn main() {
    let which = std::env::args().nth(1).unwrap_or_else(|| "res".into());
    let mut rng = Rng::new(1);
    let transposed = match which.as_str() {
        "up0" => Some((60, 80, ConvTransposeSpec::square(256, 128, 3, 2, 1, 1))),
        "up1" => Some((120, 160, ConvTransposeSpec::square(128, 64, 3, 2, 1, 1))),
        _ => None,
    };
    if which == "resmany" || which == "envresmany" {
        // 24 different layers in turn, as in a network: the weights of each
        // come from memory, not from the cache.
        let (h, w) = if which == "resmany" {
            (62, 82)
        } else {
            (32, 42)
        };
        let s = ConvSpec::square(256, 256, 3, 1, 0);
        let convs: Vec<Conv2d> = (0..24)
            .map(|_| {
                let wt = rng.normal_vec(s.weight_len(), 0.05);
                Conv2d::new(s, &wt, None, Activation::Relu).expect("layer")
            })
            .collect();
        let x = rng.tensor([1, 256, h, w]);
        let mut i = 0;
        return time_it(&format!("{which} (per layer)"), s.flops(h, w), || {
            i = (i + 1) % convs.len();
            convs[i].forward(&x).expect("forward")
        });
    }
    let head = which.strip_suffix("-unfused").unwrap_or(&which);
    if head == "head" || head == "envhead" {
        // An encoder's first two layers fused in bands (`reflect_then`), or
        // one after the other (`-unfused`): the 7×7 input conv (stride 1, or
        // 2 in the EnvMap) with reflection padding 3, then the first down
        // conv (TUNE_ALGO picks its algorithm).
        let (h, w) = (240, 320);
        let first = ConvSpec::square(3, 64, 7, if head == "head" { 1 } else { 2 }, 0);
        let down = ConvSpec::square(64, 128, 3, 2, 1);
        let firstl = Conv2d::new(
            first,
            &rng.normal_vec(first.weight_len(), 0.05),
            None,
            Activation::Relu,
        )
        .expect("layer");
        let downl = Conv2d::with_algorithm(
            Isa::best(),
            algo_from_env(),
            down,
            &rng.normal_vec(down.weight_len(), 0.05),
            None,
            Activation::Relu,
        )
        .expect("layer");
        println!("{which}: down conv {:?}", downl.algorithm());
        let x = rng.tensor([1, 3, h, w]);
        let (h1, w1) = first.out_hw(h + 6, w + 6).expect("shape");
        let flops = first.flops(h + 6, w + 6) + down.flops(h1, w1);
        if head != which {
            return time_it(&which, flops, || {
                downl
                    .forward(&firstl.forward_reflect(&x, 3, None).expect("forward"))
                    .expect("forward")
            });
        }
        return time_it(&which, flops, || {
            firstl.reflect_then(&x, 3, &downl).expect("forward")
        });
    }
    if which == "dectail" || which == "dectail-unfused" {
        // A decoder's last two layers: `up1` then the 7×7 `decout` with
        // reflection padding 3, fused in bands or one after the other.
        let (h, w) = (120, 160);
        let up = ConvTransposeSpec::square(128, 64, 3, 2, 1, 1);
        let out = ConvSpec::square(64, 3, 7, 1, 0);
        let upl = ConvTranspose2d::new(
            up,
            &rng.normal_vec(up.weight_len(), 0.05),
            None,
            Activation::Relu,
        )
        .expect("layer");
        let outl = Conv2d::new(
            out,
            &rng.normal_vec(out.weight_len(), 0.05),
            None,
            Activation::Tanh,
        )
        .expect("layer");
        let x = rng.tensor([1, up.c_in, h, w]);
        let flops = up.flops(h, w) + out.flops(2 * h + 6, 2 * w + 6);
        if which == "dectail" {
            return time_it(&which, flops, || {
                upl.then_reflect_conv(&x, &outl, 3).expect("forward")
            });
        }
        return time_it(&which, flops, || {
            outl.forward_reflect(&upl.forward(&x).expect("forward"), 3, None)
                .expect("forward")
        });
    }
    if let Some((h, w, s)) = transposed {
        let wt = rng.normal_vec(s.weight_len(), 0.05);
        let conv = ConvTranspose2d::new(s, &wt, None, Activation::Relu).expect("layer");
        let x = rng.tensor([1, s.c_in, h, w]);
        return time_it(&which, s.flops(h, w), || conv.forward(&x).expect("forward"));
    }
    let (h, w, s) = match which.as_str() {
        // `TUNE_SHAPE=h,w,c_in,c_out,k,stride,pad`: any layer.
        "shape" => {
            let v: Vec<usize> = std::env::var("TUNE_SHAPE")
                .unwrap_or_default()
                .split(',')
                .filter_map(|x| x.trim().parse().ok())
                .collect();
            let [h, w, ci, co, k, st, p] = v[..] else {
                eprintln!("TUNE_SHAPE=h,w,c_in,c_out,k,stride,pad");
                std::process::exit(2);
            };
            (h, w, ConvSpec::square(ci, co, k, st, p))
        }
        "res" => (62, 82, ConvSpec::square(256, 256, 3, 1, 0)),
        "envres" => (32, 42, ConvSpec::square(256, 256, 3, 1, 0)),
        "decout" => (246, 326, ConvSpec::square(64, 3, 7, 1, 0)),
        "encin" => (246, 326, ConvSpec::square(3, 64, 7, 1, 0)),
        "down0" => (240, 320, ConvSpec::square(64, 128, 3, 2, 1)),
        "down1" => (120, 160, ConvSpec::square(128, 256, 3, 2, 1)),
        "envin" => (246, 326, ConvSpec::square(3, 64, 7, 2, 0)),
        "envdown0" => (120, 160, ConvSpec::square(64, 128, 3, 2, 1)),
        "envdown1" => (60, 80, ConvSpec::square(128, 256, 3, 2, 1)),
        other => {
            eprintln!("unknown layer {other:?}: use res, resmany, envres, envresmany, shape, decout, encin, down0, down1, envin, envdown0, envdown1, up0, up1, head, envhead, dectail or dectail-unfused");
            std::process::exit(2);
        }
    };
    let wt = rng.normal_vec(s.weight_len(), 0.05);
    let algo = algo_from_env();
    let conv =
        Conv2d::with_algorithm(Isa::best(), algo, s, &wt, None, Activation::Relu).expect("layer");
    println!("{which}: {:?}", conv.algorithm());
    let x = rng.tensor([1, s.c_in, h, w]);
    time_it(&which, s.flops(h, w), || conv.forward(&x).expect("forward"));
}

/// TUNE_ALGO=gemm|direct|winograd|winograd-lazy|winograd6|winograd6-lazy|winograd5|winograd5-lazy|winograd-auto|winograd-s2|winograd-s2-lazy|winograd5-s2|winograd5-s2-lazy|shifted|pixtile
/// forces an algorithm.
fn algo_from_env() -> ConvAlgorithm {
    match std::env::var("TUNE_ALGO").as_deref() {
        Ok("gemm") => ConvAlgorithm::Gemm,
        Ok("direct") => ConvAlgorithm::Direct,
        Ok("winograd") => ConvAlgorithm::Winograd,
        Ok("winograd-lazy") => ConvAlgorithm::WinogradLowMemory,
        Ok("winograd6") => ConvAlgorithm::Winograd6,
        Ok("winograd6-lazy") => ConvAlgorithm::Winograd6LowMemory,
        Ok("winograd5") => ConvAlgorithm::Winograd5,
        Ok("winograd5-lazy") => ConvAlgorithm::Winograd5LowMemory,
        Ok("winograd-auto") => ConvAlgorithm::WinogradLowMemoryAutoTile,
        Ok("winograd-s2") => ConvAlgorithm::WinogradStride2,
        Ok("winograd-s2-lazy") => ConvAlgorithm::WinogradStride2LowMemory,
        Ok("winograd5-s2") => ConvAlgorithm::Winograd5Stride2,
        Ok("winograd5-s2-lazy") => ConvAlgorithm::Winograd5Stride2LowMemory,
        Ok("shifted") => ConvAlgorithm::Shifted,
        Ok("pixtile") => ConvAlgorithm::PixelTiles,
        _ => ConvAlgorithm::Auto,
    }
}
