//! `float32` tensors in and out of `TensorProto`.

use onnx_protobuf::TensorProto;
use onnx_protobuf::tensor_proto::{DataLocation, DataType};

/// A float tensor named `name` of shape `dims`, its values little-endian in `raw_data` (as
/// torch's exporter and `onnx.numpy_helper` store them).
pub(crate) fn float_tensor(name: &str, dims: &[usize], values: &[f32]) -> TensorProto {
    let mut t = TensorProto::new();
    t.name = name.to_owned();
    t.dims = dims.iter().map(|&d| d as i64).collect();
    t.data_type = DataType::FLOAT as i32;
    t.raw_data = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    t
}

/// A decoded float tensor.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Floats {
    pub dims: Vec<usize>,
    pub values: Vec<f32>,
}

impl Floats {
    /// Flat index of the first NaN or infinity.
    pub fn first_non_finite(&self) -> Option<usize> {
        self.values.iter().position(|v| !v.is_finite())
    }
}

/// The values of `t`, which must be a self-contained `float32` tensor whose data matches its
/// shape; `Err` says why not.
pub(crate) fn read_floats(t: &TensorProto) -> Result<Floats, String> {
    if t.data_location.enum_value_or_default() == DataLocation::EXTERNAL || !t.external_data.is_empty() {
        return Err("its data is in an external file; save the model self-contained \
                    (onnx.save(model, path, save_as_external_data=False))"
            .to_owned());
    }
    if t.data_type != DataType::FLOAT as i32 {
        let name = protobuf::Enum::from_i32(t.data_type)
            .map_or_else(|| format!("code {}", t.data_type), |d: DataType| format!("{d:?}"));
        return Err(format!("data type {name}, not FLOAT (float32)"));
    }
    let mut dims = Vec::with_capacity(t.dims.len());
    let mut count = 1usize;
    for &d in &t.dims {
        let d = usize::try_from(d).map_err(|_| format!("negative dimension {d} in {:?}", t.dims))?;
        count = count.checked_mul(d).ok_or_else(|| format!("shape {:?} overflows", t.dims))?;
        dims.push(d);
    }
    let values: Vec<f32> = if t.raw_data.is_empty() {
        t.float_data.clone()
    } else {
        if !t.raw_data.len().is_multiple_of(4) {
            return Err(format!("raw_data of {} bytes is not a whole number of float32", t.raw_data.len()));
        }
        t.raw_data.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect()
    };
    if values.len() != count {
        return Err(format!("shape {:?} needs {count} values, the tensor holds {}", t.dims, values.len()));
    }
    Ok(Floats { dims, values })
}
