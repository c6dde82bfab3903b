//! Query strings as the OGC services and the tile routes read them: keys
//! in any case; a key given twice alike is one, given twice differently it
//! is refused.

use std::collections::HashMap;

/// Query parameters with upper-cased keys. A key given twice alike (a
/// client adding `SERVICE=WMS` to a URL that has it) is one; given twice
/// differently it is ambiguous, to be refused ([`Params::conflict`]).
pub(super) struct Params {
    values: HashMap<String, String>,
    /// The first key given two different values, and the two.
    conflict: Option<(String, [String; 2])>,
}

impl Params {
    pub(super) fn new(query: &str) -> Params {
        let mut values: HashMap<String, String> = HashMap::new();
        let mut conflict = None;
        for (k, v) in form_urlencoded::parse(query.as_bytes()) {
            if k.is_empty() {
                continue;
            }
            let key = k.to_ascii_uppercase();
            match values.get(&key) {
                None => _ = values.insert(key, v.into_owned()),
                Some(first) if first.trim().eq_ignore_ascii_case(v.trim()) => {}
                Some(first) => _ = conflict.get_or_insert_with(|| (key, [first.clone(), v.into_owned()])),
            }
        }
        Params { values, conflict }
    }

    /// Parameters given by name (upper case) rather than in a query: a
    /// RESTful request's path.
    pub(super) fn of<'a>(pairs: impl IntoIterator<Item = (&'a str, &'a str)>) -> Params {
        let values = pairs.into_iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
        Params { values, conflict: None }
    }

    pub(super) fn get(&self, key: &str) -> Option<&str> {
        self.values.get(key).map(String::as_str)
    }

    /// The first key given two different values, and a message saying so.
    pub(super) fn conflict(&self) -> Option<(&str, String)> {
        let (key, [first, second]) = self.conflict.as_ref()?;
        Some((key, format!("{key} is given twice, as {first:?} and {second:?}: give it once")))
    }
}
