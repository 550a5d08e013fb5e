//! Train / test splits (DESIGN §2 "Test split"): whole objects go to test, so no test
//! object is ever seen in training from another azimuth; inside every setting the
//! LLFF-style held-out views are every `view_stride`-th view (0, 16, 32 of 34).
use crate::error::{Error, Result};
use crate::rng::Stream;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet};

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct SettingEntry {
    /// The setting directory name, `<uid>_<theta0>`.
    pub setting: String,
    pub object: String,
    pub views: usize,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Splits {
    pub view_stride: usize,
    pub train: Vec<String>,
    pub test: Vec<String>,
    pub test_views: BTreeMap<String, Vec<usize>>,
    pub test_objects: Vec<String>,
    pub seed: u64,
}

const TEST_OBJECTS_STREAM: u64 = 0x5e11_7500;
const SUBSET_STREAM: u64 = 0x5e11_5b5e;

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

/// Every `stride`-th view index below `views`.
pub fn test_views(views: usize, stride: usize) -> Vec<usize> {
    (0..views).step_by(stride.max(1)).collect()
}

/// Split settings by object. `test_objects` overrides the seeded choice of
/// round(test_fraction · objects) objects (at least one, and one left for training,
/// when there are two or more objects and the fraction is positive).
pub fn make_splits(
    settings: &[SettingEntry],
    view_stride: usize,
    test_fraction: f64,
    test_objects: Option<&[String]>,
    seed: u64,
) -> Result<Splits> {
    if view_stride == 0 {
        return Err(Error::Value("view_stride must be at least 1".into()));
    }
    if !(0.0..=1.0).contains(&test_fraction) {
        return Err(Error::Value(format!(
            "test_fraction {test_fraction} is outside [0, 1]"
        )));
    }
    let objects: Vec<String> = settings
        .iter()
        .map(|s| s.object.clone())
        .collect::<BTreeSet<_>>()
        .into_iter()
        .collect();
    let chosen: BTreeSet<String> = match test_objects {
        Some(list) => {
            if let Some(o) = list.iter().find(|o| !objects.contains(o)) {
                return Err(Error::Value(format!(
                    "test object {o:?} is not among the built objects"
                )));
            }
            list.iter().cloned().collect()
        }
        None => {
            let n = objects.len();
            let mut k = (test_fraction * n as f64).round() as usize;
            if n >= 2 && test_fraction > 0.0 {
                k = k.clamp(1, n - 1);
            } else if n < 2 {
                k = 0;
            }
            seeded_order(&objects, seed, TEST_OBJECTS_STREAM)
                .into_iter()
                .take(k)
                .collect()
        }
    };
    let (mut train, mut test) = (Vec::new(), Vec::new());
    let mut tv = BTreeMap::new();
    for s in settings {
        if chosen.contains(&s.object) {
            test.push(s.setting.clone());
        } else {
            train.push(s.setting.clone());
        }
        tv.insert(s.setting.clone(), test_views(s.views, view_stride));
    }
    train.sort();
    test.sort();
    Ok(Splits {
        view_stride,
        train,
        test,
        test_views: tv,
        test_objects: chosen.into_iter().collect(),
        seed,
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
    fn objects_never_straddle_and_choice_is_seeded() -> Result<()> {
        let e = entries(10, 4);
        let s = make_splits(&e, 16, 0.2, None, 1)?;
        assert_eq!(s.test_objects.len(), 2);
        assert_eq!(s.test.len(), 8);
        assert_eq!(s.train.len() + s.test.len(), 40);
        for t in &s.test {
            let obj = t.rsplit_once('_').map(|x| x.0).unwrap_or_default();
            assert!(!s.train.iter().any(|x| x.starts_with(&format!("{obj}_"))));
        }
        assert_eq!(s, make_splits(&e, 16, 0.2, None, 1)?);
        let mut shuffled = e.clone();
        shuffled.reverse();
        assert_eq!(
            s.test_objects,
            make_splits(&shuffled, 16, 0.2, None, 1)?.test_objects
        );
        Ok(())
    }

    #[test]
    fn small_builds_and_explicit_lists() -> Result<()> {
        assert!(make_splits(&entries(1, 4), 16, 0.2, None, 0)?
            .test
            .is_empty());
        let two = make_splits(&entries(2, 1), 16, 0.2, None, 0)?;
        assert_eq!((two.train.len(), two.test.len()), (1, 1));
        let list = vec!["obj1".to_string()];
        let s = make_splits(&entries(3, 2), 16, 0.2, Some(&list), 0)?;
        assert_eq!(s.test, vec!["obj1_0", "obj1_90"]);
        let bad = vec!["nope".to_string()];
        assert!(make_splits(&entries(3, 2), 16, 0.2, Some(&bad), 0).is_err());
        Ok(())
    }
}
