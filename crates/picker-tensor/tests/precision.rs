//! The process-wide precision switch (its own test binary: it changes what
//! every later `Conv2d::new` builds, so it must not run beside other tests).

use picker_tensor::{
    precision, set_precision, Activation, Conv2d, ConvAlgorithm, ConvSpec, Precision, Rng,
};

#[test]
fn precision_switch_picks_the_bf16_winograd() {
    let mut rng = Rng::new(4);
    let build = |spec: ConvSpec, rng: &mut Rng| {
        Conv2d::new(
            spec,
            &rng.normal_vec(spec.weight_len(), 0.1),
            None,
            Activation::Relu,
        )
        .unwrap()
        .algorithm()
    };
    let res = ConvSpec::square(32, 32, 3, 1, 1);
    let strided = ConvSpec::square(32, 32, 3, 2, 1);
    assert_eq!(Precision::parse("BF16"), Some(Precision::Bf16));
    assert_eq!(Precision::parse("f32"), Some(Precision::F32));
    assert_eq!(Precision::parse("f16"), None);
    if std::env::var_os("PICKER_PRECISION").is_none() {
        assert_eq!(precision(), Precision::F32);
    }
    if !Precision::Bf16.is_available() {
        eprintln!("SKIPPED: this CPU lacks AVX512_BF16; only the refusal is tested");
        let err = set_precision(Precision::Bf16).unwrap_err().to_string();
        assert!(err.contains("AVX512_BF16"), "{err}");
        assert_eq!(build(res, &mut rng), ConvAlgorithm::Winograd);
        return;
    }
    set_precision(Precision::Bf16).unwrap();
    assert_eq!(precision(), Precision::Bf16);
    assert_eq!(build(res, &mut rng), ConvAlgorithm::WinogradBf16);
    // Only the stride-1 Winograd layers change precision.
    // (AVX512_BF16 implies the AVX-512 family, whose 3×3 stride-2 layers
    // take the f32 stride-2 Winograd.)
    let lazy = std::env::var("PICKER_WINOGRAD_WEIGHTS").as_deref() == Ok("lazy")
        || std::env::var("PICKER_MEMORY").as_deref() == Ok("low");
    // (5×5 tiles unless PICKER_WINOGRAD_S2_TILE=4.)
    let four = std::env::var("PICKER_WINOGRAD_S2_TILE").as_deref() == Ok("4");
    assert_eq!(
        build(strided, &mut rng),
        match (four, lazy) {
            (false, true) => ConvAlgorithm::Winograd5Stride2LowMemory,
            (false, false) => ConvAlgorithm::Winograd5Stride2,
            (true, true) => ConvAlgorithm::WinogradStride2LowMemory,
            (true, false) => ConvAlgorithm::WinogradStride2,
        }
    );
    set_precision(Precision::F32).unwrap();
    assert_eq!(build(res, &mut rng), ConvAlgorithm::Winograd);
}
