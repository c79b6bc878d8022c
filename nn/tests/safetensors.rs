//! Safetensors round trip, PyTorch naming, and clear errors for corrupt or mismatched files.

mod common;

use std::collections::HashMap;

use dynlab_nn::{Activation, Init, METADATA_SIZES, Mlp, MlpSpec, NnError};
use safetensors::tensor::{Dtype, SafeTensors, TensorView};

fn pushing() -> Mlp {
    Mlp::new(
        MlpSpec::uniform(6, &[100, 100], 3, Activation::Tanh).unwrap(),
        Init::Auto,
        9,
    )
}

/// Serialises arbitrary tensors with the safetensors crate (as PyTorch's `save_file` would).
fn file(
    tensors: &[(&str, Dtype, Vec<usize>, Vec<u8>)],
    meta: Option<HashMap<String, String>>,
) -> Vec<u8> {
    let views: Vec<_> = tensors
        .iter()
        .map(|(n, d, s, b)| (n.to_string(), TensorView::new(*d, s.clone(), b).unwrap()))
        .collect();
    safetensors::serialize(views, meta).unwrap()
}

fn f32_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// The tensors of `mlp` as raw entries, to corrupt one at a time.
fn entries(mlp: &Mlp) -> Vec<(String, Dtype, Vec<usize>, Vec<u8>)> {
    mlp.named_tensors("")
        .into_iter()
        .map(|(n, s, v)| (n, Dtype::F32, s, f32_bytes(v)))
        .collect()
}

fn as_refs(e: &[(String, Dtype, Vec<usize>, Vec<u8>)]) -> Vec<(&str, Dtype, Vec<usize>, Vec<u8>)> {
    e.iter()
        .map(|(n, d, s, b)| (n.as_str(), *d, s.clone(), b.clone()))
        .collect()
}

#[test]
fn round_trip_preserves_architecture_and_every_bit() {
    for mlp in [
        pushing(),
        Mlp::new(
            MlpSpec::uniform(8, &[64; 8], 3, Activation::Gelu).unwrap(),
            Init::Auto,
            2,
        ),
        Mlp::new(
            MlpSpec::new(&[3, 5, 4, 2], &[Activation::Relu, Activation::Identity]).unwrap(),
            Init::Auto,
            3,
        ),
    ] {
        let bytes = mlp.to_safetensors().unwrap();
        let back = Mlp::from_safetensors(&bytes).unwrap();
        assert_eq!(back, mlp);
        // Names and shapes as PyTorch's nn.Linear in a ModuleList called `layers`.
        let st = SafeTensors::deserialize(&bytes).unwrap();
        let w0 = st.tensor("layers.0.weight").unwrap();
        assert_eq!(w0.shape(), &[mlp.sizes()[1], mlp.sizes()[0]]);
        assert_eq!(
            st.tensor("layers.0.bias").unwrap().shape(),
            &[mlp.sizes()[1]]
        );
        assert_eq!(st.len(), 2 * mlp.n_layers());
    }
}

#[test]
fn save_and_load_through_a_file() {
    let dir = std::env::temp_dir().join(format!("dynlab-nn-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("net.safetensors");
    let mlp = pushing();
    mlp.save(&path).unwrap();
    assert_eq!(Mlp::load(&path).unwrap(), mlp);
    std::fs::remove_dir_all(&dir).unwrap();
    assert!(matches!(Mlp::load(&path), Err(NnError::Io { .. })));
}

#[test]
fn loads_a_file_without_metadata_into_a_declared_architecture() {
    // A PyTorch state_dict saved with safetensors has no dynlab metadata.
    let src = pushing();
    let bytes = file(&as_refs(&entries(&src)), None);
    assert!(matches!(
        Mlp::from_safetensors(&bytes),
        Err(NnError::MissingMetadata { .. })
    ));
    let mut dst = Mlp::zeros(src.spec().clone());
    dst.load_safetensors(&bytes).unwrap();
    assert_eq!(dst.params(), src.params());
}

#[test]
fn prefixed_networks_share_one_file() {
    let a = pushing();
    let b = Mlp::new(
        MlpSpec::uniform(6, &[16], 3, Activation::Gelu).unwrap(),
        Init::Auto,
        1,
    );
    let mut all: Vec<(String, Dtype, Vec<usize>, Vec<u8>)> = Vec::new();
    for (prefix, m) in [("residual.", &a), ("field.", &b)] {
        all.extend(
            m.named_tensors(prefix)
                .into_iter()
                .map(|(n, s, v)| (n, Dtype::F32, s, f32_bytes(v))),
        );
    }
    let bytes = file(&as_refs(&all), None);
    let st = SafeTensors::deserialize(&bytes).unwrap();
    let mut a2 = Mlp::zeros(a.spec().clone());
    let mut b2 = Mlp::zeros(b.spec().clone());
    a2.load_tensors(&st, "residual.").unwrap();
    b2.load_tensors(&st, "field.").unwrap();
    assert_eq!((a2.params(), b2.params()), (a.params(), b.params()));
}

#[test]
fn corrupt_and_mismatched_files_give_errors_naming_the_tensor() {
    let mlp = pushing();
    let good = entries(&mlp);
    let mut dst = Mlp::zeros(mlp.spec().clone());

    // Truncated file, garbage, empty.
    let bytes = mlp.to_safetensors().unwrap();
    for bad in [
        &bytes[..bytes.len() - 10],
        &bytes[..5],
        b"not a safetensors file at all".as_slice(),
        &[],
    ] {
        let e = Mlp::from_safetensors(bad).unwrap_err();
        assert!(matches!(e, NnError::Safetensors(_)), "{e}");
        assert!(dst.load_safetensors(bad).is_err());
    }

    // NaN in a weight.
    let mut e = good.clone();
    let mut w: Vec<f32> = e[2]
        .3
        .chunks(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    w[17] = f32::NAN;
    e[2].3 = f32_bytes(&w);
    let err = dst.load_safetensors(&file(&as_refs(&e), None)).unwrap_err();
    assert!(
        matches!(&err, NnError::NonFinite { name, index: 17, .. } if name == "layers.1.weight"),
        "{err}"
    );
    assert!(err.to_string().contains("layers.1.weight"));
    assert!(
        dst.params().iter().all(|&p| p == 0.0),
        "parameters changed by a failed load"
    );

    // Transposed weight (PyTorch stores [out, in]).
    let mut e = good.clone();
    e[0].2 = vec![6, 100];
    let err = dst.load_safetensors(&file(&as_refs(&e), None)).unwrap_err();
    assert!(
        matches!(&err, NnError::TensorShape { name, expected, got } if name == "layers.0.weight" && expected == &vec![100, 6] && got == &vec![6, 100]),
        "{err}"
    );

    // Wrong dtype.
    let mut e = good.clone();
    e[5] = ("layers.2.bias".into(), Dtype::F64, vec![3], vec![0u8; 24]);
    let err = dst.load_safetensors(&file(&as_refs(&e), None)).unwrap_err();
    assert!(
        matches!(&err, NnError::TensorDtype { name, .. } if name == "layers.2.bias"),
        "{err}"
    );

    // Missing tensor.
    let e: Vec<_> = good
        .iter()
        .filter(|t| t.0 != "layers.1.bias")
        .cloned()
        .collect();
    let err = dst.load_safetensors(&file(&as_refs(&e), None)).unwrap_err();
    assert!(
        matches!(&err, NnError::MissingTensor { name } if name == "layers.1.bias"),
        "{err}"
    );

    // One layer too many.
    let mut e = good.clone();
    e.push((
        "layers.3.bias".into(),
        Dtype::F32,
        vec![3],
        f32_bytes(&[0.0; 3]),
    ));
    let err = dst.load_safetensors(&file(&as_refs(&e), None)).unwrap_err();
    assert!(
        matches!(&err, NnError::UnexpectedTensor { name, .. } if name == "layers.3.bias"),
        "{err}"
    );

    // Metadata that contradicts itself or is unparsable.
    for (sizes, acts) in [
        ("6,100,x,3", "tanh,tanh"),
        ("6,100,100,3", "tanh,swish"),
        ("6,100,100,3", "tanh"),
    ] {
        let meta = HashMap::from([
            (METADATA_SIZES.to_string(), sizes.to_string()),
            (
                dynlab_nn::METADATA_ACTIVATIONS.to_string(),
                acts.to_string(),
            ),
        ]);
        let err = Mlp::from_safetensors(&file(&as_refs(&good), Some(meta))).unwrap_err();
        assert!(
            matches!(err, NnError::BadMetadata { .. }),
            "{sizes} {acts}: {err}"
        );
    }
    // The untouched entries still load.
    dst.load_safetensors(&file(&as_refs(&good), None)).unwrap();
    assert_eq!(dst.params(), mlp.params());
}

/// Regression: the architecture metadata was written in hash-map order, so the same network gave
/// different file bytes from call to call (and run to run).
#[test]
fn same_network_gives_the_same_bytes_every_time() {
    let spec = MlpSpec::uniform(6, &[100, 100], 3, Activation::Tanh).unwrap();
    let mlp = Mlp::new(spec, Init::Auto, 3);
    let first = mlp.to_safetensors().unwrap();
    for _ in 0..20 {
        assert_eq!(mlp.to_safetensors().unwrap(), first);
    }
    let back = Mlp::from_safetensors(&first).unwrap();
    assert_eq!(back.params(), mlp.params());
    assert_eq!(back.sizes(), mlp.sizes());
}
