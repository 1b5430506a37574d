//! Named physical parameters: listing them with units, overriding them by name, and the
//! range checks every plant's constructor runs.

use crate::error::{PlantError, Result};

/// One parameter: `(name, value, unit)`.
pub type ParamInfo = (&'static str, f64, &'static str);

/// A parameter set whose fields can be listed and overridden by name.
///
/// Implemented by every plant's params struct (through the crate-private `param_table!`
/// macro), so names are exactly the struct's field names.
pub trait Parameters {
    /// Name of the system these parameters belong to.
    const SYSTEM: &'static str;
    /// Every parameter with its current value and unit.
    fn list(&self) -> Vec<ParamInfo>;
    /// Set one parameter by name. Unknown names are [`PlantError::UnknownParameter`];
    /// non-finite values are [`PlantError::InvalidParameter`]. Range checks happen in
    /// the plant's constructor.
    fn set(&mut self, name: &str, value: f64) -> Result<()>;
}

/// Implements [`Parameters`] for a struct of `f64` fields.
macro_rules! param_table {
    ($params:ty, $system:expr, [$(($field:ident, $unit:expr)),* $(,)?]) => {
        impl $crate::params::Parameters for $params {
            const SYSTEM: &'static str = $system;
            fn list(&self) -> Vec<$crate::params::ParamInfo> {
                vec![$((stringify!($field), self.$field, $unit)),*]
            }
            fn set(&mut self, name: &str, value: f64) -> $crate::error::Result<()> {
                let slot = match name {
                    $(stringify!($field) => &mut self.$field,)*
                    _ => {
                        return Err($crate::error::PlantError::UnknownParameter {
                            system: $system,
                            name: name.to_string(),
                        })
                    }
                };
                if !value.is_finite() {
                    return Err($crate::error::PlantError::InvalidParameter {
                        system: $system,
                        name: name.to_string(),
                        value,
                        reason: "must be finite",
                    });
                }
                *slot = value;
                Ok(())
            }
        }
    };
}
pub(crate) use param_table;

/// Error unless `value` is finite and `> 0`.
pub(crate) fn positive(system: &'static str, name: &str, value: f64) -> Result<()> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(PlantError::InvalidParameter {
            system,
            name: name.to_string(),
            value,
            reason: "must be positive and finite",
        })
    }
}

/// Error unless `value` is finite and `≥ 0`.
pub(crate) fn non_negative(system: &'static str, name: &str, value: f64) -> Result<()> {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err(PlantError::InvalidParameter {
            system,
            name: name.to_string(),
            value,
            reason: "must be non-negative and finite",
        })
    }
}
