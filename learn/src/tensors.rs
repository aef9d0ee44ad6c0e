//! Small conversions between `Vec<f32>` and burn tensors.

use burn::tensor::{Device, Tensor, TensorData};

/// A `[rows, cols]` tensor from row-major data.
pub fn tensor2(data: &[f32], rows: usize, cols: usize, device: &Device) -> Tensor<2> {
    assert_eq!(
        data.len(),
        rows * cols,
        "tensor2: {} values for {rows}x{cols}",
        data.len()
    );
    Tensor::from_data(TensorData::new(data.to_vec(), [rows, cols]), device)
}

/// A `[len]` tensor.
pub fn tensor1(data: &[f32], device: &Device) -> Tensor<1> {
    Tensor::from_data(TensorData::new(data.to_vec(), [data.len()]), device)
}

/// The values of a float tensor, row-major.
pub fn to_vec<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data()
        .convert::<f32>()
        .try_into_vec::<f32>()
        .expect("float tensor data")
}

/// The single value of a one-element tensor.
pub fn scalar<const D: usize>(t: Tensor<D>) -> f32 {
    let v = to_vec(t);
    assert_eq!(v.len(), 1, "scalar of a {}-element tensor", v.len());
    v[0]
}
