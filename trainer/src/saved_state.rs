//! A checkpoint's named tensors read back into a learner: each one present, and of the shape
//! of what it is copied into. libtorch's own copy broadcasts a smaller tensor over a larger
//! one and its scalar reads panic on an empty tensor, so a checkpoint of another network
//! (consistent, with valid checksums) would otherwise fill the state silently or abort.

use std::collections::HashMap;

use tch::{TchError, Tensor};

/// The tensor saved under `key`.
pub(crate) fn saved<'a>(named: &'a HashMap<String, Tensor>, key: &str) -> Result<&'a Tensor, TchError> {
    named.get(key).ok_or_else(|| TchError::FileFormat(format!("the checkpoint's state lacks {key}")))
}

/// Copies the tensor saved under `key` into `dst` (without gradient), refusing another shape.
pub(crate) fn restore_into(
    dst: &mut Tensor,
    named: &HashMap<String, Tensor>,
    key: &str,
) -> Result<(), TchError> {
    let src = saved(named, key)?;
    if src.size() != dst.size() {
        return Err(TchError::FileFormat(format!(
            "the checkpoint's {key} has shape {:?}, this learner's {:?}",
            src.size(),
            dst.size()
        )));
    }
    tch::no_grad(|| dst.f_copy_(src))
}

/// The one number saved under `key`.
pub(crate) fn saved_i64(named: &HashMap<String, Tensor>, key: &str) -> Result<i64, TchError> {
    one_element(saved(named, key)?, key)?.f_int64_value(&[0])
}

/// The one number saved under `key`, as f64.
pub(crate) fn saved_f64(named: &HashMap<String, Tensor>, key: &str) -> Result<f64, TchError> {
    one_element(saved(named, key)?, key)?.f_double_value(&[0])
}

fn one_element<'a>(t: &'a Tensor, key: &str) -> Result<&'a Tensor, TchError> {
    if t.size() != [1] {
        return Err(TchError::FileFormat(format!(
            "the checkpoint's {key} has shape {:?}, not one number",
            t.size()
        )));
    }
    Ok(t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use tch::Kind;

    #[test]
    fn another_shape_or_a_missing_or_empty_entry_is_an_error_and_the_same_shape_copies() {
        let mut named = HashMap::new();
        named.insert("m".to_owned(), Tensor::ones([4], (Kind::Float, tch::Device::Cpu)));
        named.insert("short".to_owned(), Tensor::ones([1], (Kind::Float, tch::Device::Cpu)));
        named.insert("step".to_owned(), Tensor::from_slice(&[7i64]));
        named.insert("empty".to_owned(), Tensor::from_slice::<i64>(&[]));
        let mut dst = Tensor::zeros([4], (Kind::Float, tch::Device::Cpu));
        restore_into(&mut dst, &named, "m").expect("same shape");
        assert_eq!(dst.sum(Kind::Float).double_value(&[]), 4.0);
        let err = restore_into(&mut dst, &named, "short").expect_err("a [1] would broadcast").to_string();
        assert!(err.contains("short has shape [1], this learner's [4]"), "{err}");
        assert!(
            restore_into(&mut dst, &named, "absent")
                .expect_err("missing")
                .to_string()
                .contains("lacks absent")
        );
        assert_eq!(saved_i64(&named, "step").expect("one number"), 7);
        assert!(saved_i64(&named, "empty").expect_err("empty").to_string().contains("not one number"));
        assert!(saved_f64(&named, "m").is_err(), "four numbers are not one");
    }
}
