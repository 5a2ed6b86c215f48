//! The words `--model` takes, from calib's registries (the `causes!` registry's [`Cause::ALL`] and
//! [`LearnedKind::ALL`]): one source for `robocal calibrate --help` and the Python package's
//! docstring (the native module exports [`cause_words`] and [`learned_words`]), so that a cause
//! added to calib appears in both without a hand-written list.

use calib::model::extensions::Cause;
use calib::model::learned::LearnedKind;

/// The cause words (`joint_compliance`, …), in the order diagnose tries them.
pub fn cause_words() -> Vec<&'static str> {
    Cause::ALL.iter().map(|c| c.name()).collect()
}

/// The learned residual kinds, as written after `learned:` (`poly`, `kernel`, …).
pub fn learned_words() -> Vec<&'static str> {
    LearnedKind::ALL.iter().map(|k| k.name()).collect()
}

/// The help of `--model`, naming every registered cause and learned kind.
pub fn model_help() -> String {
    let causes = cause_words();
    format!(
        "Error model: `kinematic` (joint error twists, zero offsets, base and target), a `+`-joined \
         extension such as `kinematic+{}` with any of the causes {} (each at only some of its \
         joints with `@`, 1-based: `{}@2,4`), a learned residual `learned:{}`, or `auto` (what \
         diagnose chooses, then the learned residual when it pays)",
        causes.iter().take(2).copied().collect::<Vec<_>>().join("+"),
        causes
            .iter()
            .map(|c| format!("`{c}`"))
            .collect::<Vec<_>>()
            .join(", "),
        causes.first().copied().unwrap_or("cause"),
        learned_words().join("|")
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_help_names_every_registered_cause_and_learned_kind() {
        let help = model_help();
        for c in Cause::ALL {
            assert!(help.contains(&format!("`{}`", c.name())), "{c}: {help}");
        }
        for k in LearnedKind::ALL {
            assert!(help.contains(k.name()), "{k}: {help}");
        }
        assert!(
            help.contains("`auto`") && help.contains("`kinematic`"),
            "{help}"
        );
        assert!(help.contains("@2,4"), "{help}");
    }
}
