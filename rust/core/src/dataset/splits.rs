//! Train / test splits (DESIGN §2 "Test split"): whole objects go to test, so no test
//! object is ever seen in training from another azimuth, or (the paper's protocol)
//! N random settings do; inside every setting the LLFF-style held-out views are every
//! `view_stride`-th view (0, 16, 32 of 34), `llffhold` for the LLFF loaders.
use crate::error::{Error, Result};
use crate::rng::Stream;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet};

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct SettingEntry {
    /// The setting directory name, `<uid>_<theta0>`.
    pub setting: String,
    pub object: String,
    pub views: usize,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
pub struct Splits {
    pub view_stride: usize,
    pub train: Vec<String>,
    pub test: Vec<String>,
    pub test_views: BTreeMap<String, Vec<usize>>,
    pub test_objects: Vec<String>,
    pub seed: u64,
    /// `objects` (whole objects held out) or `settings` (N random settings).
    pub holdout: String,
    /// N of `--test-settings` (the settings held out are `test`: fewer when the
    /// build has fewer, one always left for training).
    pub test_settings: Option<usize>,
    /// What the blur levels hold at the test views: `sharp` (Deblur-NeRF's convention,
    /// copies of the sharp image) or `blurry`.
    pub test_view_images: String,
}

/// How the test settings are chosen (the options `--test-objects` / `--test-settings`).
#[derive(Clone, Debug, PartialEq)]
pub enum Holdout<'a> {
    /// A seeded fraction of the objects, or the objects listed.
    Objects {
        fraction: f64,
        list: Option<&'a [String]>,
    },
    /// N seeded random settings (the paper's 52 of its build).
    Settings(usize),
}

const TEST_OBJECTS_STREAM: u64 = 0x5e11_7500;
const SUBSET_STREAM: u64 = 0x5e11_5b5e;
const TEST_SETTINGS_STREAM: u64 = 0x5e11_7e57;

/// A seeded permutation of ids (Fisher–Yates over their sorted order): it depends on
/// the seed and the set of ids only, never on the order they were listed or built in.
pub fn seeded_order(ids: &[String], seed: u64, stream: u64) -> Vec<String> {
    let mut order: Vec<String> = ids
        .iter()
        .cloned()
        .collect::<BTreeSet<_>>()
        .into_iter()
        .collect();
    let mut s = Stream::new(seed, stream);
    for i in (1..order.len()).rev() {
        let j = (s.uniform() * (i + 1) as f64) as usize;
        order.swap(i, j.min(i));
    }
    order
}

/// A seeded random subset of `k` ids (all of them when k ≥ their number), sorted.
/// Growing k keeps the smaller subset: the first k of one seeded order.
pub fn seeded_subset(ids: &[String], k: usize, seed: u64) -> Vec<String> {
    let mut chosen: Vec<String> = seeded_order(ids, seed, SUBSET_STREAM)
        .into_iter()
        .take(k)
        .collect();
    chosen.sort();
    chosen
}

pub use crate::ground::names::test_views;

/// The test settings chosen by `holdout` among `settings`, and the test objects: whole
/// objects (drawn or listed: see [`drawn_objects`], [`listed_objects`]), or N seeded
/// random settings (at most all but one) and no test object.
fn chosen_settings(
    settings: &[SettingEntry],
    holdout: &Holdout,
    seed: u64,
) -> Result<(BTreeSet<String>, Vec<String>)> {
    let objects: Vec<String> = settings
        .iter()
        .map(|s| s.object.clone())
        .collect::<BTreeSet<_>>()
        .into_iter()
        .collect();
    let chosen = match holdout {
        Holdout::Objects {
            list: Some(list), ..
        } => listed_objects(&objects, list)?,
        Holdout::Objects {
            fraction,
            list: None,
        } => drawn_objects(&objects, *fraction, seed)?,
        Holdout::Settings(n) => return Ok((drawn_settings(settings, *n, seed), Vec::new())),
    };
    let test = settings
        .iter()
        .filter(|s| chosen.contains(&s.object))
        .map(|s| s.setting.clone())
        .collect();
    Ok((test, chosen.into_iter().collect()))
}

/// The objects listed, each of which must have been built.
fn listed_objects(objects: &[String], list: &[String]) -> Result<BTreeSet<String>> {
    if let Some(o) = list.iter().find(|o| !objects.contains(o)) {
        return Err(Error::Value(format!(
            "test object {o:?} is not among the built objects"
        )));
    }
    Ok(list.iter().cloned().collect())
}

/// A seeded round(fraction · objects) of the objects: at least one, and one left for
/// training, when there are two or more and the fraction is positive; none of one.
fn drawn_objects(objects: &[String], fraction: f64, seed: u64) -> Result<BTreeSet<String>> {
    if !(0.0..=1.0).contains(&fraction) {
        return Err(Error::Value(format!(
            "test fraction {fraction} is outside [0, 1]"
        )));
    }
    let n = objects.len();
    let mut k = (fraction * n as f64).round() as usize;
    if n >= 2 && fraction > 0.0 {
        k = k.clamp(1, n - 1);
    } else if n < 2 {
        k = 0;
    }
    Ok(seeded_order(objects, seed, TEST_OBJECTS_STREAM)
        .into_iter()
        .take(k)
        .collect())
}

/// N seeded random settings, at most all but one.
fn drawn_settings(settings: &[SettingEntry], n: usize, seed: u64) -> BTreeSet<String> {
    let names: Vec<String> = settings.iter().map(|s| s.setting.clone()).collect();
    let k = n.min(names.len().saturating_sub(1));
    seeded_order(&names, seed, TEST_SETTINGS_STREAM)
        .into_iter()
        .take(k)
        .collect()
}

/// Split settings into train and test by `holdout`, and hold out every
/// `view_stride`-th view of each; `sharp_test_views` records what the blur levels hold
/// at those views.
pub fn make_splits(
    settings: &[SettingEntry],
    view_stride: usize,
    holdout: &Holdout,
    sharp_test_views: bool,
    seed: u64,
) -> Result<Splits> {
    if view_stride == 0 {
        return Err(Error::Value("view_stride must be at least 1".into()));
    }
    let (chosen, test_objects) = chosen_settings(settings, holdout, seed)?;
    let (mut train, mut test) = (Vec::new(), Vec::new());
    let mut tv = BTreeMap::new();
    for s in settings {
        if chosen.contains(&s.setting) {
            test.push(s.setting.clone());
        } else {
            train.push(s.setting.clone());
        }
        tv.insert(s.setting.clone(), test_views(s.views, view_stride));
    }
    train.sort();
    test.sort();
    let (kind, test_settings) = match holdout {
        Holdout::Settings(n) => ("settings", Some(*n)),
        Holdout::Objects { .. } => ("objects", None),
    };
    Ok(Splits {
        view_stride,
        train,
        test,
        test_views: tv,
        test_objects,
        seed,
        holdout: kind.into(),
        test_settings,
        test_view_images: if sharp_test_views { "sharp" } else { "blurry" }.into(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn subsets_are_seeded_nested_and_order_free() {
        let ids: Vec<String> = (0..50).map(|i| format!("obj{i:02}")).collect();
        let mut reversed = ids.clone();
        reversed.reverse();
        let a = seeded_subset(&ids, 10, 7);
        assert_eq!(a, seeded_subset(&reversed, 10, 7));
        assert_eq!(a.len(), 10);
        assert_ne!(a, seeded_subset(&ids, 10, 8));
        let b = seeded_subset(&ids, 20, 7);
        assert!(a.iter().all(|x| b.contains(x)));
        assert_eq!(seeded_subset(&ids, 99, 7).len(), 50);
        assert!(seeded_subset(&[], 3, 7).is_empty());
    }

    fn frac(fraction: f64) -> Holdout<'static> {
        Holdout::Objects {
            fraction,
            list: None,
        }
    }

    fn listed(list: &[String]) -> Holdout<'_> {
        Holdout::Objects {
            fraction: 0.2,
            list: Some(list),
        }
    }

    #[test]
    fn n_random_settings_seeded_nested_and_one_left_for_training() -> Result<()> {
        let e = entries(30, 4);
        let s = make_splits(&e, 16, &Holdout::Settings(52), true, 3)?;
        assert_eq!((s.test.len(), s.train.len()), (52, 68));
        assert_eq!(
            (s.holdout.as_str(), s.test_settings),
            ("settings", Some(52))
        );
        assert!(s.test_objects.is_empty());
        // Settings of one object may straddle (the paper picks settings, not objects).
        let straddle = s.test.iter().any(|t| {
            let obj = t.rsplit_once('_').map(|x| x.0).unwrap_or_default();
            s.train.iter().any(|x| x.starts_with(&format!("{obj}_")))
        });
        assert!(straddle);
        let mut shuffled = e.clone();
        shuffled.reverse();
        assert_eq!(
            s,
            make_splits(&shuffled, 16, &Holdout::Settings(52), true, 3)?
        );
        assert_ne!(
            s.test,
            make_splits(&e, 16, &Holdout::Settings(52), true, 4)?.test
        );
        let fewer = make_splits(&e, 16, &Holdout::Settings(10), true, 3)?;
        assert!(
            fewer.test.iter().all(|t| s.test.contains(t)),
            "N grows the same order"
        );
        let few = make_splits(&entries(2, 1), 16, &Holdout::Settings(52), false, 3)?;
        assert_eq!((few.test.len(), few.train.len()), (1, 1));
        assert_eq!(few.test_view_images, "blurry");
        assert!(
            make_splits(&entries(1, 1), 16, &Holdout::Settings(5), true, 3)?
                .test
                .is_empty()
        );
        assert!(make_splits(&e, 16, &frac(1.5), true, 3).is_err());
        Ok(())
    }

    fn entries(objects: usize, per: usize) -> Vec<SettingEntry> {
        (0..objects)
            .flat_map(|o| {
                (0..per).map(move |k| SettingEntry {
                    setting: format!("obj{o}_{}", k * 90),
                    object: format!("obj{o}"),
                    views: 34,
                })
            })
            .collect()
    }

    #[test]
    fn test_views_every_16th() {
        assert_eq!(test_views(34, 16), vec![0, 16, 32]);
        assert_eq!(test_views(17, 16), vec![0, 16]);
    }

    #[test]
    fn the_build_stride_picks_the_test_views_of_every_setting() -> Result<()> {
        // The stride is the build's (`--test-view-stride`), not the paper's 16: every
        // setting holds out views 0, s, 2s, … below its view count, and records s.
        for stride in [1usize, 5, 8, 16, 40] {
            let s = make_splits(&entries(3, 2), stride, &frac(0.2), true, 0)?;
            assert_eq!(s.view_stride, stride);
            for (setting, views) in &s.test_views {
                let want: Vec<usize> = (0..34).step_by(stride).collect();
                assert_eq!(views, &want, "{setting}, stride {stride}");
            }
            assert_eq!(s.test_views.len(), 6);
        }
        Ok(())
    }

    #[test]
    fn objects_never_straddle_and_choice_is_seeded() -> Result<()> {
        let e = entries(10, 4);
        let s = make_splits(&e, 16, &frac(0.2), true, 1)?;
        assert_eq!(s.test_objects.len(), 2);
        assert_eq!(s.test.len(), 8);
        assert_eq!(s.train.len() + s.test.len(), 40);
        for t in &s.test {
            let obj = t.rsplit_once('_').map(|x| x.0).unwrap_or_default();
            assert!(!s.train.iter().any(|x| x.starts_with(&format!("{obj}_"))));
        }
        assert_eq!(s, make_splits(&e, 16, &frac(0.2), true, 1)?);
        let mut shuffled = e.clone();
        shuffled.reverse();
        assert_eq!(
            s.test_objects,
            make_splits(&shuffled, 16, &frac(0.2), true, 1)?.test_objects
        );
        Ok(())
    }

    #[test]
    fn small_builds_and_explicit_lists() -> Result<()> {
        assert!(make_splits(&entries(1, 4), 16, &frac(0.2), true, 0)?
            .test
            .is_empty());
        let two = make_splits(&entries(2, 1), 16, &frac(0.2), true, 0)?;
        assert_eq!((two.train.len(), two.test.len()), (1, 1));
        let list = vec!["obj1".to_string()];
        let s = make_splits(&entries(3, 2), 16, &listed(&list), true, 0)?;
        assert_eq!(s.test, vec!["obj1_0", "obj1_90"]);
        let bad = vec!["nope".to_string()];
        assert!(make_splits(&entries(3, 2), 16, &listed(&bad), true, 0).is_err());
        Ok(())
    }
}
