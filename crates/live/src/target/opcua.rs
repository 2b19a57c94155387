//! OPC UA targets: the Sinumerik temperature compensation (K3) through its setting data, and
//! generic node writes of the value at the axis's position.
//!
//! K3 (SINUMERIK 840D sl Function Manual Extended Functions, K3 4.2 Temperature compensation)
//! computes ΔKx = K0 + tanβ·(Px − P0) as an approximation of the axis's **error curve**
//! (actual-value offsets measured over the travel) and compensates it, with the sign of the
//! axis's other measuring-system compensations (LEC: "a positive compensation value causes
//! the machine axis to move in the negative direction"; docs/linear.md). So the setting data
//! carry errmap's error line (E = measured − target), not the compensation −E:
//! SD43900 K0 = the error line's value at Px (mm), SD43910 tanβ = its slope (mm per mm),
//! SD43920 P0 = Px (mm, machine coordinates). errmap's own line is in the compensation sign,
//! hence the minus signs below.

use super::{Output, Present, Target};
use crate::axis::Line;
use crate::config::{LiveConfig, TargetConfig, TargetKind};
use crate::opcua::{denied_error, node_id, ConnectError, OpcUa};
use crate::LinkError;
use errmap_core::error::{Error, Result};
use opcua::types::NodeId;
use std::collections::BTreeMap;
use std::time::Duration;

/// The nodes of one axis.
enum AxisNodes {
    /// SD43900, SD43910, SD43920.
    K3 {
        abs: NodeId,
        slope: NodeId,
        reference: NodeId,
    },
    /// One node taking the value at the position; `mm`: written in mm (else µm).
    Value { node: NodeId, mm: bool },
}

/// A target written over OPC UA: the Sinumerik K3 setting data of an axis, or generic nodes.
pub struct OpcUaTarget {
    name: String,
    kind: TargetKind,
    client: OpcUa,
    axes: BTreeMap<String, AxisNodes>,
}

/// The K3 setting data of a compensation line about Px: (SD43900 mm, SD43910, SD43920 mm).
pub fn k3_values(line: &Line, px_mm: f64) -> (f64, f64, f64) {
    (-line.offset_um / 1000.0, -line.slope_um_per_m * 1e-6, px_mm)
}

/// The compensation line about Px of K3 setting data about any P0: the error line
/// K0 + tanβ·(x − P0) = [K0 + tanβ·(Px − P0)] + tanβ·(x − Px), in the compensation sign.
pub fn line_of_k3(abs_mm: f64, slope: f64, reference_mm: f64, px_mm: f64) -> Line {
    Line {
        offset_um: -(abs_mm + slope * (px_mm - reference_mm)) * 1000.0,
        slope_um_per_m: -slope * 1e6,
    }
}

impl OpcUaTarget {
    /// Connect the target `targets[index]` of `config` (an error when the server cannot be
    /// reached or the config asks for what it cannot do).
    pub fn connect(
        config: &LiveConfig,
        index: usize,
        t: &TargetConfig,
    ) -> Result<OpcUaTarget, LinkError> {
        let key = format!("targets.{index}");
        crate::source::opcua::check_security(config, &key, t.security_policy.as_deref())?;
        let endpoint = t.endpoint.clone().ok_or_else(|| {
            config.key_error(
                &key,
                format!("a {} target needs 'endpoint'", t.kind.name()),
                "endpoint = \"opc.tcp://host:4840\"",
            )
        })?;
        let mut axes = BTreeMap::new();
        for (axis, a) in &t.axes {
            let k = format!("{key}.axes.{axis}");
            let node = |field: &str, v: &Option<String>| -> Result<NodeId> {
                let text = v.as_deref().ok_or_else(|| {
                    config.key_error(
                        &k,
                        format!("axis {axis} needs '{field}'"),
                        format!("{field} = \"ns=2;s=…\""),
                    )
                })?;
                node_id(text)
                    .map_err(|e| config.key_error(&format!("{k}.{field}"), e, "e.g. ns=2;s=…"))
            };
            let nodes = match t.kind {
                TargetKind::SinumerikOpcua => AxisNodes::K3 {
                    abs: node("sd43900", &a.sd43900)?,
                    slope: node("sd43910", &a.sd43910)?,
                    reference: node("sd43920", &a.sd43920)?,
                },
                _ => AxisNodes::Value {
                    node: node("node", &a.node)?,
                    mm: match a.unit.as_deref() {
                        None | Some("um") => false,
                        Some("mm") => true,
                        Some(other) => {
                            return Err(LinkError::Config(config.key_error(
                                &format!("{k}.unit"),
                                format!("'{other}' is not a unit"),
                                "um or mm",
                            )))
                        }
                    },
                },
            };
            axes.insert(axis.clone(), nodes);
        }
        let what = format!("OPC UA target '{}'", t.name);
        let client = OpcUa::connect(
            &what,
            &endpoint,
            t.user.as_deref(),
            t.password.as_deref(),
            Duration::from_millis(2000),
        )
        .map_err(|e| match e {
            // The login refused, as the server said: the `user` key is the one to fix.
            ConnectError::Denied(code) => LinkError::Refused(denied_error(
                config,
                &key,
                &what,
                &endpoint,
                t.user.as_deref(),
                &code,
            )),
            ConnectError::Failed(e) => LinkError::from(e),
        })?;
        Ok(OpcUaTarget {
            name: t.name.clone(),
            kind: t.kind,
            client,
            axes,
        })
    }

    fn nodes(&self, axis: &str) -> Result<&AxisNodes> {
        self.axes.get(axis).ok_or_else(|| {
            Error::usage(
                format!("target '{}' has no nodes for axis {axis}", self.name),
                format!("add [targets.axes.{axis}]"),
            )
        })
    }

    fn failed(&self, action: &'static str, e: String) -> Error {
        Error::io(
            action,
            format!("OPC UA target '{}' at {}", self.name, self.client.endpoint),
            std::io::Error::other(e),
        )
    }
}

impl Target for OpcUaTarget {
    fn name(&self) -> &str {
        &self.name
    }
    fn kind(&self) -> &'static str {
        self.kind.name()
    }
    fn is_point(&self) -> bool {
        self.kind != TargetKind::SinumerikOpcua
    }
    fn present(&mut self, axis: &str) -> Result<Present> {
        match self.nodes(axis)? {
            AxisNodes::K3 {
                abs,
                slope,
                reference,
            } => {
                let nodes = [abs.clone(), slope.clone(), reference.clone()];
                let v = self
                    .client
                    .read(&nodes)
                    .map_err(|e| self.failed("read from", e))?;
                let num = |k: usize| match v[k] {
                    crate::opcua::NodeValue::Number(x) => Ok(x),
                    crate::opcua::NodeValue::Flag(_) => {
                        Err(self.failed("read from", format!("{} is a bit", nodes[k])))
                    }
                };
                // The present line about the node's reference; the loop moves it to Px.
                Ok(Present::K3 {
                    abs_mm: num(0)?,
                    slope: num(1)?,
                    reference_mm: num(2)?,
                })
            }
            AxisNodes::Value { node, mm } => {
                let mm = *mm;
                let v = self
                    .client
                    .read(std::slice::from_ref(node))
                    .map_err(|e| self.failed("read from", e))?;
                match v[0] {
                    crate::opcua::NodeValue::Number(x) => {
                        Ok(Present::Value(if mm { x * 1000.0 } else { x }))
                    }
                    crate::opcua::NodeValue::Flag(_) => {
                        Err(self.failed("read from", format!("{node} is a bit")))
                    }
                }
            }
        }
    }
    fn write(&mut self, axis: &str, output: &Output) -> Result<()> {
        let writes: Vec<(NodeId, f64)> = match self.nodes(axis)? {
            AxisNodes::K3 {
                abs,
                slope,
                reference,
            } => {
                let (k0, tan_beta, p0) = k3_values(&output.line, output.px_mm);
                vec![
                    (reference.clone(), p0),
                    (abs.clone(), k0),
                    (slope.clone(), tan_beta),
                ]
            }
            AxisNodes::Value { node, mm } => {
                let v = output.value_um.ok_or_else(|| {
                    Error::usage("no position", "the axis needs a position channel")
                })?;
                vec![(node.clone(), if *mm { v / 1000.0 } else { v })]
            }
        };
        self.client
            .write(&writes)
            .map_err(|e| self.failed("write to", e))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn k3_signs_by_hand() {
        // errmap's model: the axis goes long beyond Px = 100 mm, tanβ = +40 µm/m (E > 0 for
        // x > Px); the compensation line is −40 µm/m. K3 takes the error line: SD43910 = +40e-6,
        // SD43900 = 0, SD43920 = 100 mm. At x = 600 mm K3's ΔK = 40e-6·500 mm = 0.02 mm, the
        // measured error, which K3 (like the LEC) moves the axis back by.
        let line = Line {
            offset_um: 0.0,
            slope_um_per_m: -40.0,
        };
        let (k0, slope, p0) = k3_values(&line, 100.0);
        assert_eq!(k0, 0.0);
        assert!((slope - 40e-6).abs() < 1e-18);
        assert_eq!(p0, 100.0);
        assert!((k0 + slope * (600.0 - p0) - 0.02).abs() < 1e-15);
        // A present K3 line about another reference comes back about Px.
        let back = line_of_k3(0.001, 40e-6, 0.0, 100.0);
        // Error at Px: 0.001 mm + 40e-6·100 mm = 0.005 mm → compensation −5 µm.
        assert!((back.offset_um + 5.0).abs() < 1e-9);
        assert!((back.slope_um_per_m + 40.0).abs() < 1e-9);
    }
}
