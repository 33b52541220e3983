//! Parallel element-wise ops.

use rayon::prelude::*;

use crate::activation::Activation;
use crate::error::{shape_err, Result};
use crate::tensor::Tensor;

const CHUNK: usize = 1 << 14;

/// Applies `act` to every element in place.
pub fn activate(x: &mut Tensor, act: Activation) {
    x.data_mut()
        .par_chunks_mut(CHUNK)
        .for_each(|c| act.apply(c));
}

/// `x += y` element-wise (shapes must agree).
pub fn add_assign(x: &mut Tensor, y: &Tensor) -> Result<()> {
    if x.shape() != y.shape() {
        return Err(shape_err(
            "add",
            "shape",
            format!("{:?}", x.shape()),
            format!("{:?}", y.shape()),
        ));
    }
    x.data_mut()
        .par_chunks_mut(CHUNK)
        .zip(y.data().par_chunks(CHUNK))
        .for_each(|(a, b)| a.iter_mut().zip(b).for_each(|(a, b)| *a += b));
    Ok(())
}
