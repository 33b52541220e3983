//! Inputs at the edges of what the public API's types admit (found by a
//! fuzz campaign of the library APIs): each is refused with an error, or
//! panics with a message where the function documents it, never wraps
//! around or indexes out of bounds.

use picker_tensor::{
    fold_batchnorm, reference, reflect_index, Activation, BatchNorm, Conv2d, ConvSpec,
    ConvTransposeSpec, Rng, Tensor, WeightLayout,
};

#[test]
fn shapes_whose_size_overflows_are_refused() {
    // Wrapping to 0 elements once let an empty Vec pass as a 2^64 tensor.
    let e = Tensor::new([1 << 32, 1 << 32, 1, 1], vec![]).unwrap_err();
    assert!(e.to_string().contains("overflows"), "{e}");
    let big = ConvSpec::square(1 << 32, 1 << 32, 1, 1, 0);
    assert_eq!(big.weight_len(), usize::MAX);
    assert!(Conv2d::new(big, &[], None, Activation::None).is_err());
    assert!(ConvSpec::square(1, 1, 3, 1, usize::MAX / 2)
        .out_hw(4, 4)
        .is_err());
    let t = ConvTransposeSpec::square(1 << 32, 1 << 32, 3, 2, 1, 1);
    assert_eq!(t.weight_len(), usize::MAX);
    assert!(ConvTransposeSpec::square(1, 1, 3, usize::MAX / 2, 1, 0)
        .out_hw(4, 4)
        .is_err());
    let x = Tensor::zeros([1, 2, 3, 4]);
    assert!(x.crop(usize::MAX, 0, 2, 1).is_err());
    assert!(x.channels(1, usize::MAX).is_err());
}

#[test]
#[should_panic(expected = "overflows")]
fn zeros_of_an_overflowing_shape_panics_with_a_message() {
    let _ = Tensor::zeros([1 << 32, 1 << 32, 1, 1]);
}

#[test]
fn reference_ops_refuse_a_bias_of_the_wrong_length() {
    let x = Tensor::zeros([1, 1, 4, 4]);
    let e = reference::conv2d(&x, &[0.0; 9], Some(&[]), ConvSpec::square(1, 1, 3, 1, 0));
    assert!(e.unwrap_err().to_string().contains("bias length"));
    let s = ConvTransposeSpec::square(1, 2, 3, 2, 1, 1);
    let e = reference::conv_transpose2d(&x, &[0.0; 18], Some(&[1.0]), s);
    assert!(e.unwrap_err().to_string().contains("bias length"));
}

#[test]
fn batchnorm_with_a_variance_that_is_not_positive_is_refused() {
    let bn = |var: f32, eps: f32| BatchNorm {
        gamma: vec![1.0],
        beta: vec![0.0],
        mean: vec![0.0],
        var: vec![var],
        eps,
    };
    for (var, eps) in [
        (-1.0, 1e-5),
        (0.0, 0.0),
        (f32::NAN, 1e-5),
        (f32::INFINITY, 0.0),
    ] {
        let e = fold_batchnorm(&[1.0], None, &bn(var, eps), WeightLayout::Conv);
        assert!(e.is_err(), "var {var} eps {eps}");
    }
    let (w, b) = fold_batchnorm(&[2.0], None, &bn(0.0, 1e-5), WeightLayout::Conv).unwrap();
    assert!(w[0].is_finite() && b[0].is_finite());
    let huge = WeightLayout::Transposed {
        kernel_area: usize::MAX,
    };
    let mut two = bn(1.0, 1e-5);
    for v in [&mut two.gamma, &mut two.beta, &mut two.mean, &mut two.var] {
        v.push(v[0]);
    }
    assert!(fold_batchnorm(&[1.0; 4], None, &two, huge).is_err());
}

#[test]
#[should_panic(expected = "empty axis")]
fn reflect_index_of_an_empty_axis_panics_with_a_message() {
    reflect_index(3, 0);
}

#[test]
fn rng_ranges_at_the_extremes() {
    let mut r = Rng::new(3);
    for _ in 0..1000 {
        assert_eq!(r.range(7, 7), 7);
        let v = r.range(usize::MAX - 1, usize::MAX);
        assert!(v >= usize::MAX - 1);
        let _ = r.range(0, usize::MAX);
    }
    assert!(std::panic::catch_unwind(|| Rng::new(1).range(5, 2)).is_err());
}
