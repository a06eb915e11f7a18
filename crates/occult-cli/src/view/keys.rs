//! The controls: which key does what, named once for the keyboard, the script and the help
//! overlay.

use winit::keyboard::KeyCode;

/// What a key does.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Action {
    /// Held: fly along the view (W), back (S), left (A), right (D), down (Q), up (E).
    Fly(Direction),
    /// Held: turn the view (arrow keys).
    Look(Direction),
    /// Fly faster (`=`) or slower (`-`), as the wheel does.
    Speed(i8),
    /// Renderer `i` of the list (keys 1 to 9).
    Renderer(usize),
    /// The next renderer of the list (Tab).
    NextRenderer,
    /// The previous renderer of the list (Shift+Tab).
    PreviousRenderer,
    /// The next display mode (M).
    NextMode,
    /// Orbit about the target on or off (O).
    Orbit,
    /// Back to the starting view (R).
    Reset,
    /// The next (N) or previous (B) view of the path.
    PathView(i8),
    /// Play the path from the current view, or stop (P).
    Play,
    /// Screenshot to PNG (X or F12).
    Screenshot,
    /// Start or stop recording the camera to a path file (C).
    Record,
    /// The statistics overlay on or off (T).
    Stats,
    /// The help overlay on or off (H or F1).
    Help,
    /// Close the window (Escape).
    Quit,
}

/// A direction of flight or of turning.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Direction {
    /// Along the view, or turning up.
    Forward,
    /// Against the view, or turning down.
    Back,
    /// To the left.
    Left,
    /// To the right.
    Right,
    /// Up along the camera's up.
    Up,
    /// Down.
    Down,
}

/// Each key with its action and the script's name for it.
const KEYS: &[(KeyCode, bool, &str, Action)] = &[
    (KeyCode::KeyW, false, "w", Action::Fly(Direction::Forward)),
    (KeyCode::KeyS, false, "s", Action::Fly(Direction::Back)),
    (KeyCode::KeyA, false, "a", Action::Fly(Direction::Left)),
    (KeyCode::KeyD, false, "d", Action::Fly(Direction::Right)),
    (KeyCode::KeyE, false, "e", Action::Fly(Direction::Up)),
    (KeyCode::KeyQ, false, "q", Action::Fly(Direction::Down)),
    (KeyCode::ArrowUp, false, "up", Action::Look(Direction::Up)),
    (KeyCode::ArrowDown, false, "down", Action::Look(Direction::Down)),
    (KeyCode::ArrowLeft, false, "left", Action::Look(Direction::Left)),
    (KeyCode::ArrowRight, false, "right", Action::Look(Direction::Right)),
    (KeyCode::Equal, false, "=", Action::Speed(1)),
    (KeyCode::Minus, false, "-", Action::Speed(-1)),
    (KeyCode::Digit1, false, "1", Action::Renderer(0)),
    (KeyCode::Digit2, false, "2", Action::Renderer(1)),
    (KeyCode::Digit3, false, "3", Action::Renderer(2)),
    (KeyCode::Digit4, false, "4", Action::Renderer(3)),
    (KeyCode::Digit5, false, "5", Action::Renderer(4)),
    (KeyCode::Digit6, false, "6", Action::Renderer(5)),
    (KeyCode::Digit7, false, "7", Action::Renderer(6)),
    (KeyCode::Digit8, false, "8", Action::Renderer(7)),
    (KeyCode::Digit9, false, "9", Action::Renderer(8)),
    (KeyCode::Tab, true, "shift+tab", Action::PreviousRenderer),
    (KeyCode::Tab, false, "tab", Action::NextRenderer),
    (KeyCode::KeyM, false, "m", Action::NextMode),
    (KeyCode::KeyO, false, "o", Action::Orbit),
    (KeyCode::KeyR, false, "r", Action::Reset),
    (KeyCode::KeyN, false, "n", Action::PathView(1)),
    (KeyCode::KeyB, false, "b", Action::PathView(-1)),
    (KeyCode::KeyP, false, "p", Action::Play),
    (KeyCode::KeyX, false, "x", Action::Screenshot),
    (KeyCode::F12, false, "f12", Action::Screenshot),
    (KeyCode::KeyC, false, "c", Action::Record),
    (KeyCode::KeyT, false, "t", Action::Stats),
    (KeyCode::KeyH, false, "h", Action::Help),
    (KeyCode::F1, false, "f1", Action::Help),
    (KeyCode::Escape, false, "escape", Action::Quit),
];

impl Action {
    /// The action of a physical key, with Shift held or not.
    pub fn from_key(code: KeyCode, shift: bool) -> Option<Action> {
        KEYS.iter()
            .find(|(k, s, _, _)| {
                *k == code && (*s == shift || (!*s && !KEYS.iter().any(|(k2, s2, _, _)| *k2 == code && *s2)))
            })
            .map(|&(_, _, _, a)| a)
    }

    /// The action of a key named as the script names it (`w`, `tab`, `shift+tab`, `f1`).
    pub fn from_name(name: &str) -> Option<Action> {
        KEYS.iter().find(|(_, _, n, _)| *n == name).map(|&(_, _, _, a)| a)
    }

    /// True for keys that act while held (flying and turning).
    pub fn is_held(self) -> bool {
        matches!(self, Action::Fly(_) | Action::Look(_))
    }
}

/// The help overlay: every control, one a line, the keys and what they do apart by a tab.
pub const HELP: &[&str] = &[
    "occult view: controls",
    "W A S D\tfly forward, left, back, right",
    "Q / E\tfly down / up",
    "mouse drag\tlook around (any button held)",
    "arrow keys\tlook around",
    "wheel, = / -\tfly faster / slower",
    "1 .. 9\trenderer 1 to 9 of the list (top right)",
    "Tab / Shift+Tab\tnext / previous renderer",
    "M\tdisplay: color, depth, item ids, exactness",
    "O\torbit about the point looked at (on/off)",
    "R\treset to the starting view",
    "N / B\tnext / previous view of the path (--path)",
    "P\tplay the path / stop",
    "X or F12\tscreenshot (PNG, as occult render writes)",
    "C\trecord the camera / stop and write the path",
    "T\tstatistics on / off",
    "H or F1\tthis help on / off",
    "Esc\tquit",
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_and_names_agree() {
        assert_eq!(Action::from_key(KeyCode::Tab, false), Some(Action::NextRenderer));
        assert_eq!(Action::from_key(KeyCode::Tab, true), Some(Action::PreviousRenderer));
        assert_eq!(
            Action::from_key(KeyCode::KeyW, true),
            Some(Action::Fly(Direction::Forward))
        );
        assert_eq!(Action::from_key(KeyCode::KeyZ, false), None);
        for (code, shift, name, action) in KEYS {
            assert_eq!(Action::from_name(name), Some(*action), "{name}");
            assert_eq!(Action::from_key(*code, *shift), Some(*action), "{name}");
        }
    }

    #[test]
    fn help_names_every_action() {
        let help = HELP.join("\n");
        for key in [
            "W A S D", "Q / E", "wheel", "1 .. 9", "Tab", "M\t", "O\t", "R\t", "N / B", "P\t", "F12", "C\t", "T\t",
            "F1", "Esc",
        ] {
            assert!(help.contains(key), "{key}");
        }
    }
}
