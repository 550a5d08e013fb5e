//! Each registered kind's levels of a build ([`crate::kinds!`]): the value of its option,
//! as the sampling config holds it (meta.json's `config.<kind>`).
use super::kind::ImageKind;
use serde::{Deserialize, Serialize};

/// The levels of every kind of the registry.
macro_rules! kind_levels {
    ({} $($module:ident :: $Kind:ident),* $(,)?) => {
        /// Each registered kind's levels of a build (its option's value), by kind.
        #[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
        pub struct KindLevels {
            $(
                #[doc = concat!("The ", stringify!($module), " levels; none in a default build.")]
                #[serde(default, skip_serializing_if = "Vec::is_empty")]
                pub $module: Vec<u32>,
            )*
        }

        impl KindLevels {
            /// Every kind's level directories, in level order.
            pub fn dirs(&self) -> Vec<String> {
                let mut dirs = Vec::new();
                $(dirs.extend(self.$module.iter().map(|&l| ImageKind::$Kind(l).dir()));)*
                dirs
            }
        }
    };
}

crate::kinds!([kind_levels] {});
