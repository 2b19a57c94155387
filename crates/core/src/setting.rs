//! Settings named in hints: a library says which setting would fix a problem, the front end
//! words it (the `errmap` binary as its command-line flag, `--units`).
//!
//! A hint such as "pass --units mm|inch" is formed deep in a library, where the condition is
//! found; threading a wording object through every operation would double every signature. So
//! each library crate declares its settings as an enum implementing [`Setting`], writes
//! `setting::words(Setting::Units)` where the hint names one, and the binary installs, once at
//! start, the function that words every setting of every crate ([`install_wording`]). Until
//! one is installed (a library used on its own, a unit test) a setting is worded by its key in
//! back-quotes, `` `units` ``.

use std::any::Any;
use std::sync::OnceLock;

/// A setting a user can give an operation, named by hints that say how to fix a problem.
pub trait Setting: Any + Copy {
    /// The setting's name in errmap's own terms (its job-file key where it has one), used
    /// when no front end words it.
    fn key(self) -> &'static str;
}

/// How a front end words a setting: given any crate's setting (as `&dyn Any`), its words, or
/// `None` for a setting the front end does not know (then the key is used).
pub type Wording = fn(&dyn Any) -> Option<&'static str>;

static WORDING: OnceLock<Wording> = OnceLock::new();

/// Installs the front end's wording of settings; the first call wins and later ones return
/// `false`. The `errmap` binary calls it before anything else.
pub fn install_wording(wording: Wording) -> bool {
    WORDING.set(wording).is_ok()
}

/// The words for `setting` in hints: the installed front end's (`--units`), else its key in
/// back-quotes (`` `units` ``).
pub fn words<S: Setting>(setting: S) -> String {
    match WORDING.get().and_then(|w| w(&setting)) {
        Some(words) => words.to_string(),
        None => format!("`{}`", setting.key()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Clone, Copy)]
    enum Example {
        Units,
    }

    impl Setting for Example {
        fn key(self) -> &'static str {
            match self {
                Example::Units => "units",
            }
        }
    }

    #[test]
    fn a_setting_is_its_key_until_a_front_end_words_it() {
        // The one test in this crate that installs a wording, so the order is known.
        assert_eq!(words(Example::Units), "`units`");
        fn flags(s: &dyn Any) -> Option<&'static str> {
            s.downcast_ref::<Example>().map(|e| match e {
                Example::Units => "--units",
            })
        }
        assert!(install_wording(flags));
        assert_eq!(words(Example::Units), "--units");
        assert!(!install_wording(flags), "the first wording stays");
    }
}
