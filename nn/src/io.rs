//! Parameters to and from safetensors, with PyTorch's tensor names.
//!
//! Layer `l` is stored as `{prefix}layers.{l}.weight` (F32, shape `[out, in]`) and
//! `{prefix}layers.{l}.bias` (F32, `[out]`), the names and shapes of a PyTorch module holding
//! `self.layers = nn.ModuleList([nn.Linear(…), …])`. Files written by [`Mlp::to_safetensors`] also
//! carry the architecture in the header metadata ([`METADATA_SIZES`], [`METADATA_ACTIVATIONS`]).

use std::collections::{BTreeMap, HashMap};
use std::ops::Range;
use std::path::Path;

use safetensors::tensor::{Dtype, SafeTensors, TensorView};

use crate::{Activation, Mlp, MlpSpec, NnError};

/// Metadata key holding the layer sizes, comma-separated (`6,100,100,3`).
pub const METADATA_SIZES: &str = "dynlab.mlp.sizes";
/// Metadata key holding the hidden activations, comma-separated (`tanh,tanh`).
pub const METADATA_ACTIVATIONS: &str = "dynlab.mlp.activations";

impl Mlp {
    /// Every parameter tensor as `(name, shape, values)`, names prefixed with `prefix` (use `""`,
    /// or for example `"residual."` when several networks share one file).
    pub fn named_tensors(&self, prefix: &str) -> Vec<(String, Vec<usize>, &[f32])> {
        self.tensor_slots(prefix)
            .into_iter()
            .map(|(name, shape, range)| (name, shape, &self.params()[range]))
            .collect()
    }

    /// `(name, shape, range in params)` of every tensor.
    fn tensor_slots(&self, prefix: &str) -> Vec<(String, Vec<usize>, Range<usize>)> {
        let mut out = Vec::with_capacity(2 * self.n_layers());
        for (l, s) in self.layer_shapes().iter().enumerate() {
            out.push((
                format!("{prefix}layers.{l}.weight"),
                vec![s.n_out, s.n_in],
                s.weight.clone(),
            ));
            out.push((
                format!("{prefix}layers.{l}.bias"),
                vec![s.n_out],
                s.bias.clone(),
            ));
        }
        out
    }

    /// Serialises the parameters (and the architecture as metadata) to safetensors bytes.
    pub fn to_safetensors(&self) -> Result<Vec<u8>, NnError> {
        let tensors: Vec<(String, Vec<usize>, Vec<u8>)> = self
            .named_tensors("")
            .into_iter()
            .map(|(name, shape, values)| {
                (
                    name,
                    shape,
                    values.iter().flat_map(|v| v.to_le_bytes()).collect(),
                )
            })
            .collect();
        let views = tensors
            .iter()
            .map(|(name, shape, bytes)| {
                Ok((
                    name.as_str(),
                    TensorView::new(Dtype::F32, shape.clone(), bytes)?,
                ))
            })
            .collect::<Result<Vec<_>, NnError>>()?;
        let mut metadata = HashMap::new();
        metadata.insert(METADATA_SIZES.to_string(), join(self.sizes()));
        metadata.insert(
            METADATA_ACTIVATIONS.to_string(),
            join(self.spec().activations()),
        );
        sort_metadata(safetensors::serialize(views, Some(metadata))?)
    }

    /// Reads a network, architecture included, from bytes written by [`Mlp::to_safetensors`].
    pub fn from_safetensors(bytes: &[u8]) -> Result<Mlp, NnError> {
        let (_, header) = SafeTensors::read_metadata(bytes)?;
        let meta = header.metadata().clone().unwrap_or_default();
        let sizes_s = meta.get(METADATA_SIZES).ok_or(NnError::MissingMetadata {
            key: METADATA_SIZES,
        })?;
        let acts_s = meta
            .get(METADATA_ACTIVATIONS)
            .ok_or(NnError::MissingMetadata {
                key: METADATA_ACTIVATIONS,
            })?;
        let sizes = split(sizes_s)
            .map(|s| s.parse::<usize>())
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| NnError::BadMetadata {
                key: METADATA_SIZES,
                value: sizes_s.clone(),
                reason: format!("expected comma-separated layer sizes like 6,100,100,3 ({e})"),
            })?;
        let acts = split(acts_s)
            .map(|s| s.parse::<Activation>())
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| NnError::BadMetadata {
                key: METADATA_ACTIVATIONS,
                value: acts_s.clone(),
                reason: e.to_string(),
            })?;
        let spec = MlpSpec::new(&sizes, &acts).map_err(|e| NnError::BadMetadata {
            key: METADATA_SIZES,
            value: format!("{sizes_s} / {acts_s}"),
            reason: e.to_string(),
        })?;
        let mut mlp = Mlp::zeros(spec);
        mlp.load_safetensors(bytes)?;
        Ok(mlp)
    }

    /// Loads parameters into this network's architecture from safetensors bytes (for example a
    /// file written by PyTorch's `safetensors.torch.save_file(model.state_dict(), …)`), checking
    /// that every `layers.{l}.weight/bias` is present, F32, of the declared shape and finite, and
    /// that no further `layers.*` tensor exists. On error the parameters are unchanged.
    pub fn load_safetensors(&mut self, bytes: &[u8]) -> Result<(), NnError> {
        let st = SafeTensors::deserialize(bytes)?;
        self.load_tensors(&st, "")
    }

    /// Loads parameters named `{prefix}layers.*` from an opened safetensors file (other names are
    /// ignored, so one file can hold several networks), with the checks of
    /// [`Mlp::load_safetensors`].
    pub fn load_tensors(&mut self, st: &SafeTensors<'_>, prefix: &str) -> Result<(), NnError> {
        let mut params = self.params().to_vec();
        let mut expected: Vec<String> = Vec::new();
        for (name, shape, range) in self.tensor_slots(prefix) {
            expected.push(name.clone());
            let view = st
                .tensor(&name)
                .map_err(|_| NnError::MissingTensor { name: name.clone() })?;
            if view.dtype() != Dtype::F32 {
                return Err(NnError::TensorDtype {
                    name,
                    got: format!("{:?}", view.dtype()),
                });
            }
            if view.shape() != shape.as_slice() {
                return Err(NnError::TensorShape {
                    name,
                    expected: shape,
                    got: view.shape().to_vec(),
                });
            }
            for (i, (dst, b)) in params[range]
                .iter_mut()
                .zip(view.data().chunks_exact(4))
                .enumerate()
            {
                let v = f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
                if !v.is_finite() {
                    return Err(NnError::NonFinite {
                        name,
                        index: i,
                        value: v,
                    });
                }
                *dst = v;
            }
        }
        let layers_prefix = format!("{prefix}layers.");
        for name in st.names() {
            if name.starts_with(&layers_prefix) && !expected.iter().any(|e| e == name) {
                return Err(NnError::UnexpectedTensor {
                    name: name.to_string(),
                    sizes: self.sizes().to_vec(),
                });
            }
        }
        self.params_mut().copy_from_slice(&params);
        Ok(())
    }

    /// Writes [`Mlp::to_safetensors`] to a file.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<(), NnError> {
        let path = path.as_ref();
        let bytes = self.to_safetensors()?;
        std::fs::write(path, bytes).map_err(|source| NnError::Io {
            path: path.to_path_buf(),
            source,
        })
    }

    /// Reads a file written by [`Mlp::save`] ([`Mlp::from_safetensors`]).
    pub fn load(path: impl AsRef<Path>) -> Result<Mlp, NnError> {
        let path = path.as_ref();
        let bytes = std::fs::read(path).map_err(|source| NnError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Mlp::from_safetensors(&bytes)
    }
}

fn join<T: std::fmt::Display>(items: &[T]) -> String {
    items
        .iter()
        .map(|i| i.to_string())
        .collect::<Vec<_>>()
        .join(",")
}

fn split(s: &str) -> impl Iterator<Item = &str> {
    s.split(',').map(str::trim).filter(|s| !s.is_empty())
}

/// `safetensors::serialize` writes the metadata map in hash order, which differs from run to run;
/// this rewrites the JSON header with the metadata keys sorted, so the same network always gives
/// the same bytes. The header keeps its length (white space pads it), so data offsets stay valid.
fn sort_metadata(mut bytes: Vec<u8>) -> Result<Vec<u8>, NnError> {
    use safetensors::SafeTensorError;
    let n = bytes
        .get(..8)
        .and_then(|b| <[u8; 8]>::try_from(b).ok())
        .map(|b| u64::from_le_bytes(b) as usize)
        .filter(|&n| bytes.len() >= 8 + n)
        .ok_or(SafeTensorError::InvalidHeaderLength)?;
    let header = &bytes[8..8 + n];
    let mut value: serde_json::Value = serde_json::from_slice(header.trim_ascii_end())
        .map_err(SafeTensorError::InvalidHeaderDeserialization)?;
    if let Some(meta) = value.get_mut("__metadata__") {
        let sorted: BTreeMap<String, serde_json::Value> =
            serde_json::from_value(meta.take()).map_err(SafeTensorError::JsonError)?;
        *meta = serde_json::to_value(sorted).map_err(SafeTensorError::JsonError)?;
    }
    let mut text = serde_json::to_vec(&value).map_err(SafeTensorError::JsonError)?;
    if text.len() > n {
        return Err(SafeTensorError::HeaderTooLarge.into());
    }
    text.resize(n, b' ');
    bytes[8..8 + n].copy_from_slice(&text);
    Ok(bytes)
}
