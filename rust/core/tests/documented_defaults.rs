//! Defaults the docs promise in prose, checked against the core's declarations (the
//! generated CLI reference follows the code by construction; these pages do not).

/// The number written after `key` on the promises page (spaces and line breaks
/// normalised), e.g. "`--max-triangles`, 5000000".
fn promised(page: &str, key: &str) -> Option<u64> {
    let text = page.split_whitespace().collect::<Vec<_>>().join(" ");
    let rest = &text[text.find(key)? + key.len()..];
    let digits: String = rest
        .trim_start_matches([',', ' '])
        .chars()
        .take_while(char::is_ascii_digit)
        .collect();
    digits.parse().ok()
}

#[test]
fn preflight_budgets_are_the_ones_the_promises_page_states() {
    let page = include_str!("../../../docs/guide/promises.md");
    let core = blurset_core::BuildConfig::default();
    assert_eq!(promised(page, "`--max-triangles`"), Some(5_000_000));
    assert_eq!(promised(page, "`--max-texture-pixels`"), Some(256 << 20));
    assert_eq!(
        Some(core.max_triangles),
        promised(page, "`--max-triangles`")
    );
    assert_eq!(
        Some(core.max_texture_pixels),
        promised(page, "`--max-texture-pixels`")
    );
}
