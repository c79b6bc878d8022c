//! The pose of one tf frame in another, over time, from a bag's `/tf` and `/tf_static`.
//!
//! [`lookup_series`] reads every `tf2_msgs/msg/TFMessage` on `/tf` and `/tf_static`, builds the
//! tf tree (each child frame has one parent) and gives the transform `parent → child` at every
//! stamp of the chain's moving link. The chain may have intermediate frames in either direction
//! (`world → odom → car`, or `map ← world → car` through a common ancestor): links are composed
//! in 3D (quaternions), inverted where the chain goes up the tree. When the chain has more than
//! one moving link, the one with the most transforms sets the stamps and each other moving link
//! is taken at its latest transform at or before that stamp (zero-order hold, no
//! interpolation); stamps before every link is known are skipped and counted.
//!
//! Transforms are returned in the order they were recorded, with their stamps as published,
//! NaN and all: what to do with a bad sample is the caller's choice.

use std::collections::HashMap;

use dynlab_msgs::geometry_msgs::{Quaternion, Transform, Vector3};
use dynlab_msgs::tf2_msgs::TFMessage;

use crate::error::BagError;
use crate::reader::Bag;

/// The topic of moving transforms.
pub const TF_TOPIC: &str = "/tf";
/// The topic of fixed transforms (latched: transient local).
pub const TF_STATIC_TOPIC: &str = "/tf_static";

/// Problems looking up a transform.
#[derive(Debug, thiserror::Error)]
pub enum TfError {
    /// The bag has neither `/tf` nor `/tf_static`.
    #[error(
        "the bag has no /tf or /tf_static topic (topics: {topics}); record tf, or give the pose \
         topic instead (--pose-topic)"
    )]
    NoTf {
        /// The topics the bag has.
        topics: String,
    },
    /// A frame does not appear in the tf tree.
    #[error("frame `{frame}` is not in the bag's tf tree; its links are: {links}")]
    UnknownFrame {
        /// The frame asked for.
        frame: String,
        /// Every `parent → child` link in the bag.
        links: String,
    },
    /// The two frames are in separate trees.
    #[error("frames `{parent}` and `{child}` are not connected in the tf tree (links: {links})")]
    NotConnected {
        /// Parent frame asked for.
        parent: String,
        /// Child frame asked for.
        child: String,
        /// Every link in the bag.
        links: String,
    },
    /// Every link of the chain is static: there is no trajectory.
    #[error(
        "the transform {parent} → {child} is static (only /tf_static links): it does not move; \
         give the frame pair of the moving body"
    )]
    Static {
        /// Parent frame.
        parent: String,
        /// Child frame.
        child: String,
    },
    /// A tf message could not be read.
    #[error(transparent)]
    Bag(#[from] BagError),
}

/// The transform `parent → child` (the child frame's pose in the parent frame) at one stamp.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TfSample {
    /// The stamp of the moving link's transform \[ns\] (its header stamp, or the log time where
    /// the header stamp is zero).
    pub t_ns: i64,
    /// Log time of the message that carried it \[ns\].
    pub log_time_ns: u64,
    /// The composed transform.
    pub transform: Transform,
}

/// The transform between two frames over time, and how it was composed.
#[derive(Debug, Clone, PartialEq)]
pub struct TfSeries {
    /// The frames of the chain, from `parent` to `child`.
    pub chain: Vec<String>,
    /// The moving link whose stamps the samples have, as `parent → child`.
    pub driving_link: String,
    /// The samples, in recording order.
    pub samples: Vec<TfSample>,
    /// Stamps of the driving link skipped because another moving link had no transform yet.
    pub skipped_before_chain: usize,
    /// What a person should know (links with two parents, held links).
    pub notes: Vec<String>,
}

struct Link {
    parent: String,
    is_static: bool,
    /// `(stamp, log time, transform)` in recording order.
    samples: Vec<(i64, u64, Transform)>,
}

fn frame_name(name: &str) -> &str {
    name.strip_prefix('/').unwrap_or(name)
}

/// The transform `parent → child` at every stamp of the chain's moving link; see the module
/// docs.
pub fn lookup_series(bag: &Bag, parent: &str, child: &str) -> Result<TfSeries, TfError> {
    let (parent, child) = (frame_name(parent), frame_name(child));
    let mut links: HashMap<String, Link> = HashMap::new();
    let mut order: Vec<String> = Vec::new();
    let mut notes = Vec::new();
    let mut any = false;
    for (topic, is_static) in [(TF_STATIC_TOPIC, true), (TF_TOPIC, false)] {
        if bag.topic(topic).is_none() {
            continue;
        }
        any = true;
        for m in bag.read::<TFMessage>(topic)? {
            for t in m.msg.transforms {
                let c = frame_name(&t.child_frame_id).to_string();
                let p = frame_name(&t.header.frame_id).to_string();
                let stamp = t.header.stamp.to_nanos();
                let stamp = if stamp != 0 {
                    stamp
                } else {
                    i64::try_from(m.log_time_ns).unwrap_or(i64::MAX)
                };
                let link = links.entry(c.clone()).or_insert_with(|| {
                    order.push(c.clone());
                    Link {
                        parent: p.clone(),
                        is_static,
                        samples: Vec::new(),
                    }
                });
                if link.parent != p {
                    let note = format!(
                        "frame `{c}` has two parents (`{}` and `{p}`): the transforms from `{p}` \
                         are ignored",
                        link.parent
                    );
                    if !notes.contains(&note) {
                        notes.push(note);
                    }
                    continue;
                }
                link.is_static &= is_static;
                link.samples.push((stamp, m.log_time_ns, t.transform));
            }
        }
    }
    if !any {
        return Err(TfError::NoTf {
            topics: bag
                .topics()
                .iter()
                .map(|t| t.name.as_str())
                .collect::<Vec<_>>()
                .join(", "),
        });
    }
    let list = || {
        let v: Vec<String> = order
            .iter()
            .map(|c| format!("{} → {c}", links[c].parent))
            .collect();
        if v.is_empty() {
            "none".to_string()
        } else {
            v.join(", ")
        }
    };
    let known = |f: &str| links.contains_key(f) || links.values().any(|l| l.parent == f);
    for f in [parent, child] {
        if !known(f) {
            return Err(TfError::UnknownFrame {
                frame: f.to_string(),
                links: list(),
            });
        }
    }
    // Frames from `f` up to the root.
    let ancestors = |f: &str| -> Vec<String> {
        let mut out = vec![f.to_string()];
        while let Some(l) = links.get(out.last().map(String::as_str).unwrap_or_default()) {
            if out.contains(&l.parent) {
                break; // a cycle: malformed tree
            }
            out.push(l.parent.clone());
        }
        out
    };
    let up_child = ancestors(child);
    let up_parent = ancestors(parent);
    let Some(common) = up_child.iter().find(|f| up_parent.contains(f)).cloned() else {
        return Err(TfError::NotConnected {
            parent: parent.into(),
            child: child.into(),
            links: list(),
        });
    };
    // Links from the common ancestor down to each end, named by their child frame.
    let down = |up: &[String]| -> Vec<String> {
        let k = up.iter().position(|f| *f == common).unwrap_or(0);
        up[..k].iter().rev().cloned().collect()
    };
    let to_child = down(&up_child);
    let to_parent = down(&up_parent);
    let mut chain: Vec<String> =
        up_parent[..=up_parent.iter().position(|f| *f == common).unwrap_or(0)].to_vec();
    chain.extend(to_child.iter().cloned());

    let moving: Vec<&String> = to_child
        .iter()
        .rev()
        .chain(to_parent.iter().rev())
        .filter(|c| !links[*c].is_static)
        .collect();
    // The moving link with the most transforms sets the stamps (the one nearest the child on
    // ties).
    let Some(best) = moving.iter().map(|c| links[*c].samples.len()).max() else {
        return Err(TfError::Static {
            parent: parent.into(),
            child: child.into(),
        });
    };
    let driving = moving
        .iter()
        .find(|c| links[**c].samples.len() == best)
        .map(|c| (*c).clone())
        .unwrap_or_default();
    // Other links, sorted by stamp for the zero-order hold.
    let held: HashMap<&str, Vec<(i64, Transform)>> = to_child
        .iter()
        .chain(&to_parent)
        .filter(|c| **c != driving)
        .map(|c| {
            let mut v: Vec<(i64, Transform)> =
                links[c].samples.iter().map(|s| (s.0, s.2)).collect();
            if links[c].is_static {
                // a static link holds at every time: keep its last transform only
                v = v.last().map(|&(_, t)| vec![(i64::MIN, t)]).unwrap_or_default();
            } else {
                v.sort_by_key(|s| s.0);
                notes.push(format!(
                    "link {} → {c} also moves: held at its latest transform at each stamp of {} → {driving}",
                    links[c].parent, links[&driving].parent
                ));
            }
            (c.as_str(), v)
        })
        .collect();
    let mut samples = Vec::with_capacity(links[&driving].samples.len());
    let mut skipped = 0;
    'stamps: for &(t, log, tr) in &links[&driving].samples {
        let at = |c: &str| -> Option<Transform> {
            if c == driving {
                return Some(tr);
            }
            let v = held.get(c)?;
            let k = v.partition_point(|s| s.0 <= t);
            k.checked_sub(1).map(|k| v[k].1)
        };
        // Composed only where there is more than one link, so a direct link's transform comes
        // out bit for bit as recorded.
        let down = |links: &[String]| -> Option<Option<Transform>> {
            let mut acc: Option<Transform> = None;
            for c in links {
                let x = at(c)?;
                acc = Some(match acc {
                    None => x,
                    Some(a) => compose(&a, &x),
                });
            }
            Some(acc)
        };
        let (Some(a_child), Some(a_parent)) = (down(&to_child), down(&to_parent)) else {
            skipped += 1;
            continue 'stamps;
        };
        let transform = match (a_parent, a_child) {
            (None, Some(c)) => c,
            (Some(p), Some(c)) => compose(&inverse(&p), &c),
            (Some(p), None) => inverse(&p),
            (None, None) => IDENTITY,
        };
        samples.push(TfSample {
            t_ns: t,
            log_time_ns: log,
            transform,
        });
    }
    Ok(TfSeries {
        chain,
        driving_link: format!("{} → {driving}", links[&driving].parent),
        samples,
        skipped_before_chain: skipped,
        notes,
    })
}

const IDENTITY: Transform = Transform {
    translation: Vector3 {
        x: 0.0,
        y: 0.0,
        z: 0.0,
    },
    rotation: Quaternion::IDENTITY,
};

fn normalized(q: &Quaternion) -> Quaternion {
    let n = (q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w).sqrt();
    if n > 0.0 {
        Quaternion {
            x: q.x / n,
            y: q.y / n,
            z: q.z / n,
            w: q.w / n,
        }
    } else {
        *q
    }
}

fn mul(a: &Quaternion, b: &Quaternion) -> Quaternion {
    Quaternion {
        w: a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z,
        x: a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y,
        y: a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x,
        z: a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w,
    }
}

fn conj(q: &Quaternion) -> Quaternion {
    Quaternion {
        x: -q.x,
        y: -q.y,
        z: -q.z,
        w: q.w,
    }
}

/// `v` rotated by the unit quaternion `q`.
fn rotate(q: &Quaternion, v: &Vector3) -> Vector3 {
    let p = Quaternion {
        x: v.x,
        y: v.y,
        z: v.z,
        w: 0.0,
    };
    let r = mul(&mul(q, &p), &conj(q));
    Vector3 {
        x: r.x,
        y: r.y,
        z: r.z,
    }
}

/// `a ∘ b`: the pose `b`, given in the frame whose pose is `a`, in `a`'s parent frame.
pub fn compose(a: &Transform, b: &Transform) -> Transform {
    let qa = normalized(&a.rotation);
    let r = rotate(&qa, &b.translation);
    Transform {
        translation: Vector3 {
            x: a.translation.x + r.x,
            y: a.translation.y + r.y,
            z: a.translation.z + r.z,
        },
        rotation: normalized(&mul(&qa, &normalized(&b.rotation))),
    }
}

/// The inverse transform: `compose(t, inverse(t))` is the identity.
pub fn inverse(t: &Transform) -> Transform {
    let qi = conj(&normalized(&t.rotation));
    let r = rotate(&qi, &t.translation);
    Transform {
        translation: Vector3 {
            x: -r.x,
            y: -r.y,
            z: -r.z,
        },
        rotation: qi,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compose_and_inverse_agree_with_planar_geometry() {
        let a = Transform::planar(1.0, 2.0, 0.5);
        let b = Transform::planar(0.3, -0.1, 0.25);
        let c = compose(&a, &b);
        let (s, co) = 0.5f64.sin_cos();
        assert!((c.translation.x - (1.0 + co * 0.3 - s * -0.1)).abs() < 1e-12);
        assert!((c.translation.y - (2.0 + s * 0.3 + co * -0.1)).abs() < 1e-12);
        assert!((c.rotation.yaw() - 0.75).abs() < 1e-12);
        let id = compose(&c, &inverse(&c));
        assert!(id.translation.x.abs() < 1e-12 && id.translation.y.abs() < 1e-12);
        assert!(id.rotation.yaw().abs() < 1e-12);
    }
}
