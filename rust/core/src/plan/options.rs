//! One declaration per option (issue 27): a config struct's table (`build_options!` of
//! [`super::config`], `noise_options!` of the noise config) gives each field its type,
//! default and range ([`Spec`]) and, in a [`Meta`], its flags, help, whether it shapes
//! the outputs and how it reads on the command line. [`config_struct!`] makes the
//! struct, its defaults, its checks and [`OptionInfo`] records of it; the CLI parser, the
//! list of options that shape the outputs, TOML keys and the CLI reference are made from
//! those records (python/blurset/options.py), never listed again.
use super::spec::{Kind, OptionValue, Spec};
use serde::Serialize;

/// What a declaration says of an option beyond its type, default and range. Written as
/// `{ help: "…", flags: &["--keep-linear"], … }` in a table; what is left out is
/// [`Meta::none`]'s.
pub struct Meta<T> {
    /// The flags that set it, the first the one errors name; none given: `--<name>`
    /// with dashes.
    pub flags: &'static [&'static str],
    /// No flag of its own: the flag of this other option sets it (`latents_auto` is
    /// `--latents auto`).
    pub via: Option<&'static str>,
    /// No flag: a key of a TOML file only.
    pub toml_only: bool,
    /// How the flag reads its text, when the field's type and range do not say it.
    pub kind: Option<Kind>,
    /// The help of its flag: what it does, in the user's words (the default is added).
    pub help: &'static str,
    /// What a None default means, in words (`every licence`).
    pub unset: Option<&'static str>,
    /// The value a recorded config without this option was made with (blurset before
    /// the option, when that is not its default).
    pub before: Option<T>,
    /// Its default under `--demo`, when that has its own.
    pub demo: Option<T>,
    /// Options whose flags exclude each other share a group name.
    pub group: Option<&'static str>,
    /// The flag's value as usage shows it (default: the name in capitals).
    pub metavar: Option<&'static str>,
    /// The titled section of the help its flag is listed under (none: the command's).
    pub section: Option<&'static str>,
}

impl<T> Meta<T> {
    pub fn none() -> Meta<T> {
        Meta {
            flags: &[],
            via: None,
            toml_only: false,
            kind: None,
            help: "",
            unset: None,
            before: None,
            demo: None,
            group: None,
            metavar: None,
            section: None,
        }
    }
}

/// One option as its declaration states it: what the parsers, the help, the docs and
/// the rerun check are made from (exposed to Python as `OptionDecl`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct OptionInfo {
    pub name: &'static str,
    /// The field's Rust type as the table writes it (`Option<Vec<String>>`).
    pub rust_type: &'static str,
    /// Its flags (none: set through `via`'s flag, or a TOML key only).
    pub flags: Vec<String>,
    /// The option whose flag sets this one.
    pub via: Option<&'static str>,
    /// The keys a TOML file may name it by (dashes or underscores alike): its name and
    /// the names of its flags.
    pub keys: Vec<String>,
    pub kind: Kind,
    /// None is a value of it (its unset state).
    pub optional: bool,
    /// The values of a `Choice`.
    pub choices: Vec<&'static str>,
    /// The accepted values, as an error states them.
    pub range: String,
    /// The default, as dataset.json records the option.
    pub default: serde_json::Value,
    pub unset: Option<&'static str>,
    /// The default under `--demo`, when it has its own.
    pub demo: Option<serde_json::Value>,
    /// The value a recorded config without this option was made with: the declared
    /// one, or the default.
    pub before: serde_json::Value,
    pub help: &'static str,
    /// Whether it shapes the files a build writes (a rerun into the same output must
    /// keep it); the others decide only where and how a build runs.
    pub shapes_outputs: bool,
    pub group: Option<&'static str>,
    pub metavar: Option<&'static str>,
    /// The titled section of the help its flag is listed under.
    pub section: Option<&'static str>,
}

impl OptionInfo {
    /// The record of option `name`, a field of type `T` with `default` under `spec`.
    pub fn new<T: OptionValue + Serialize>(
        name: &'static str,
        rust_type: &'static str,
        default: &T,
        spec: &Spec,
        shapes_outputs: bool,
        meta: Meta<T>,
    ) -> OptionInfo {
        let value = |v: &T| serde_json::to_value(v).unwrap_or_default();
        let flags: Vec<String> = if meta.toml_only || meta.via.is_some() {
            Vec::new()
        } else if meta.flags.is_empty() {
            vec![format!("--{}", name.replace('_', "-"))]
        } else {
            meta.flags.iter().map(|f| f.to_string()).collect()
        };
        let mut keys = vec![name.to_string()];
        for f in &flags {
            let key = f.trim_start_matches('-').replace('-', "_");
            if !keys.contains(&key) {
                keys.push(key);
            }
        }
        let default_value = value(default);
        OptionInfo {
            name,
            rust_type,
            flags,
            via: meta.via,
            keys,
            kind: meta.kind.unwrap_or_else(|| T::kind(spec)),
            optional: T::optional(),
            choices: match spec {
                Spec::Choice(c) => c.to_vec(),
                _ => Vec::new(),
            },
            range: spec.expected(),
            before: meta.before.as_ref().map_or(default_value.clone(), value),
            default: default_value,
            unset: meta.unset,
            demo: meta.demo.as_ref().map(value),
            help: meta.help,
            shapes_outputs,
            group: meta.group,
            metavar: meta.metavar,
            section: meta.section,
        }
    }
}

/// `shapes` or `run` in a table: whether the option shapes the outputs.
macro_rules! shapes_outputs {
    (shapes) => {
        true
    };
    (run) => {
        false
    };
}
pub(crate) use shapes_outputs;

/// The config struct of a table (`build_options!`): its fields with their defaults, the
/// conversion of a value as given ([`super::spec::Raw`]) under each field's [`Spec`], the
/// range check of every field and the [`OptionInfo`] of each. An entry reads
/// `name: Type = default, spec, shapes|run { meta };`.
macro_rules! config_struct {
    (
        $(#[doc = $sdoc:expr])*
        $cfg:ident, $command:literal;
        $(
            $(#[doc = $doc:expr])*
            $name:ident : $ty:ty = $default:expr, $spec:expr, $shape:ident
                { $($k:ident : $v:expr),* $(,)? };
        )*
    ) => {
        $(#[doc = $sdoc])*
        #[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
        #[serde(default, deny_unknown_fields)]
        pub struct $cfg {
            $( $(#[doc = $doc])* pub $name: $ty, )*
        }

        impl Default for $cfg {
            fn default() -> Self {
                $cfg { $( $name: $default, )* }
            }
        }

        impl $cfg {
            /// The option names, in declaration order.
            pub const OPTIONS: &'static [&'static str] = &[$(stringify!($name)),*];

            fn set(&mut self, option: &str, raw: &Raw) -> Result<()> {
                match option {
                    $( stringify!($name) => self.$name = convert(option, raw, &$spec)?, )*
                    _ => return Err(config_error(
                        option,
                        concat!("is not an option of ", $command).into(),
                    )),
                }
                Ok(())
            }

            fn check_fields(&self) -> Result<()> {
                $( check(stringify!($name), &self.$name, &$spec)?; )*
                Ok(())
            }

            /// Every option as its declaration states it, in declaration order.
            pub fn declarations() -> Vec<OptionInfo> {
                let d = Self::default();
                vec![$(
                    OptionInfo::new::<$ty>(
                        stringify!($name),
                        stringify!($ty),
                        &d.$name,
                        &$spec,
                        shapes_outputs!($shape),
                        Meta { $($k: $v,)* ..Meta::none() },
                    ),
                )*]
            }
        }
    };
}
pub(crate) use config_struct;

/// What every table must hold, checked by each config's tests: a flag or a way to the
/// option for each, help for every flag and none that speaks of the project's history,
/// no flag or key named twice, declared `before` values only on options that shape the
/// outputs, and a demo default that is a valid value.
#[cfg(test)]
pub(crate) fn check_declarations(decls: &[OptionInfo]) -> std::result::Result<(), String> {
    let mut seen: Vec<String> = Vec::new();
    for d in decls {
        for k in d.flags.iter().chain(&d.keys) {
            if seen.contains(k) {
                return Err(format!("{}: {k} names two options", d.name));
            }
            seen.push(k.clone());
        }
        if let Some(via) = d.via {
            match decls.iter().find(|o| o.name == via) {
                Some(o) if !o.flags.is_empty() => {}
                _ => return Err(format!("{}: via {via}, which has no flag", d.name)),
            }
        }
        if !d.flags.is_empty() {
            if d.help.trim().is_empty() {
                return Err(format!("{}: a flag without help", d.name));
            }
            if let Some(f) = d.flags.iter().find(|f| !f.starts_with("--")) {
                return Err(format!("{}: flag {f} does not start with --", d.name));
            }
            let low = d.help.to_lowercase();
            if low.contains("issue") || low.contains("builds before") || low.contains("(default") {
                return Err(format!(
                    "{}: help speaks of history or states a default",
                    d.name
                ));
            }
        }
        if d.optional && d.default.is_null() && d.unset.is_none() && !d.flags.is_empty() {
            let companion = decls.iter().any(|o| o.via == Some(d.name));
            if !companion && !d.help.contains("required") {
                return Err(format!("{}: a None default without `unset` words", d.name));
            }
        }
        if d.before != d.default && !d.shapes_outputs {
            return Err(format!(
                "{}: `before` on an option that shapes nothing",
                d.name
            ));
        }
        if d.kind == Kind::Choice && d.choices.is_empty() {
            return Err(format!("{}: a choice without choices", d.name));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    //! Adding an option is one declaration: a toy table of two entries makes a config
    //! struct whose defaults, conversion, range check and [`OptionInfo`] records all
    //! come from those entries (the parsers and docs are made from the records).
    use super::*;
    use crate::error::Result;
    use crate::plan::spec::{check, config_error, convert, Raw};
    use serde::Deserialize;
    use std::collections::BTreeMap;

    config_struct! {
        /// A toy config: one declaration per option, nothing else.
        ToyConfig, "toy";
        /// A toy option that shapes the outputs.
        width: u32 = 3, Spec::int(1, 10), shapes {
            help: "toy width",
            demo: Some(2),
            before: Some(1),
        };
        toy_mode: String = "a".into(), Spec::Choice(&["a", "b"]), run {
            flags: &["--mode", "--toy-mode"],
            help: "toy mode",
        };
    }

    impl ToyConfig {
        fn from_values(values: &BTreeMap<String, Raw>) -> Result<ToyConfig> {
            let mut c = ToyConfig::default();
            for (k, v) in values {
                c.set(k, v)?;
            }
            c.check_fields()?;
            Ok(c)
        }
    }

    #[test]
    fn a_toy_option_is_one_declaration() -> Result<()> {
        assert_eq!(ToyConfig::OPTIONS, ["width", "toy_mode"]);
        assert_eq!(
            ToyConfig::default(),
            ToyConfig {
                width: 3,
                toy_mode: "a".into()
            }
        );
        let decls = ToyConfig::declarations();
        check_declarations(&decls).map_err(crate::error::Error::Value)?;
        let w = &decls[0];
        assert_eq!((w.name, w.rust_type, w.kind), ("width", "u32", Kind::Int));
        assert_eq!(w.flags, ["--width"]);
        assert_eq!(w.keys, ["width"]);
        assert_eq!(w.default, serde_json::json!(3));
        assert_eq!(w.demo, Some(serde_json::json!(2)));
        assert_eq!(w.before, serde_json::json!(1));
        assert_eq!(w.range, "must be an integer in 1..=10");
        assert!(w.shapes_outputs && !w.optional);
        let m = &decls[1];
        assert_eq!((m.kind, m.choices.clone()), (Kind::Choice, vec!["a", "b"]));
        assert_eq!(m.flags, ["--mode", "--toy-mode"]);
        assert_eq!(m.keys, ["toy_mode", "mode"]);
        assert!(!m.shapes_outputs && m.before == m.default);
        // The conversion and the range check are the declaration's too.
        let one = |k: &str, v: Raw| BTreeMap::from([(k.to_string(), v)]);
        assert_eq!(ToyConfig::from_values(&one("width", Raw::Int(7)))?.width, 7);
        let err = |k: &str, v: Raw| {
            ToyConfig::from_values(&one(k, v))
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default()
        };
        assert_eq!(
            err("width", Raw::Int(11)),
            "width 11: must be an integer in 1..=10"
        );
        assert!(err("toy_mode", Raw::Str("c".into())).contains("one of a, b"));
        assert_eq!(err("depth", Raw::Int(1)), "depth is not an option of toy");
        Ok(())
    }
}
