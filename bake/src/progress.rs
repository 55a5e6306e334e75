//! Progress bars for the long stages of a bake (indicatif), or none at all
//! (tests, `--quiet`): every stage asks [`Progress::bar`] for a bar and ticks it.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// Whether and where bake stages draw progress bars.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Progress {
    visible: bool,
}

impl Progress {
    /// No bars (tests, scripts).
    pub const fn hidden() -> Self {
        Self { visible: false }
    }

    /// Bars on standard error.
    pub const fn stderr() -> Self {
        Self { visible: true }
    }

    /// A bar of `len` steps of `unit` labelled `stage`; hidden when progress is off.
    pub fn bar(&self, stage: &str, len: u64, unit: &str) -> ProgressBar {
        if !self.visible {
            return ProgressBar::hidden();
        }
        let bar = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::stderr());
        let template = format!("{{msg:>10}} [{{bar:40}}] {{pos}}/{{len}} {unit}, {{elapsed}} (eta {{eta}})");
        bar.set_style(
            ProgressStyle::with_template(&template).unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        bar.set_message(stage.to_string());
        bar
    }
}
