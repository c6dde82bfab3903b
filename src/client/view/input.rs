//! The keys and the mouse as the viewer last saw them, turned into what the
//! controls take: the movement keys held ([`Held`]) and the drag since the
//! last cursor position. Losing the window's focus releases everything, so
//! no key stays held while another window has it.

use super::controls::Held;
use std::collections::HashSet;
use winit::keyboard::KeyCode;

/// Keys down, the left button and the cursor.
#[derive(Clone, Debug, Default)]
pub struct Input {
    keys: HashSet<KeyCode>,
    dragging: bool,
    cursor: Option<(f64, f64)>,
}

impl Input {
    /// A key went down or up.
    pub fn key(&mut self, key: KeyCode, pressed: bool) {
        if pressed {
            self.keys.insert(key);
        } else {
            self.keys.remove(&key);
        }
    }

    /// The left button went down or up.
    pub fn button(&mut self, pressed: bool) {
        self.dragging = pressed;
    }

    /// The cursor moved to `(x, y)`: the drag since its last position, if
    /// the left button is down.
    pub fn moved(&mut self, x: f64, y: f64) -> Option<(f64, f64)> {
        let last = self.cursor.replace((x, y))?;
        self.dragging.then_some((x - last.0, y - last.1))
    }

    /// The window lost focus: nothing is held any more.
    pub fn release_all(&mut self) {
        *self = Input::default();
    }

    /// The movement the keys held ask for: W/S or ↑/↓, A/D, Q/E, ←/→,
    /// R/F, Shift.
    pub fn held(&self) -> Held {
        let down = |set: &[KeyCode]| set.iter().any(|k| self.keys.contains(k));
        let axis = |minus: &[KeyCode], plus: &[KeyCode]| i8::from(down(plus)) - i8::from(down(minus));
        Held {
            forward: axis(&[KeyCode::KeyS, KeyCode::ArrowDown], &[KeyCode::KeyW, KeyCode::ArrowUp]),
            right: axis(&[KeyCode::KeyA], &[KeyCode::KeyD]),
            up: axis(&[KeyCode::KeyQ], &[KeyCode::KeyE]),
            turn: axis(&[KeyCode::ArrowLeft], &[KeyCode::ArrowRight]),
            tilt: axis(&[KeyCode::KeyF], &[KeyCode::KeyR]),
            boost: down(&[KeyCode::ShiftLeft, KeyCode::ShiftRight]),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_a_left_drag_looks() {
        let mut input = Input::default();
        assert_eq!(input.moved(10.0, 10.0), None);
        assert_eq!(input.moved(30.0, 5.0), None, "moving without the button");
        input.button(true);
        assert_eq!(input.moved(35.0, 7.0), Some((5.0, 2.0)));
        assert_eq!(input.moved(35.0, 10.0), Some((0.0, 3.0)));
        input.button(false);
        assert_eq!(input.moved(50.0, 50.0), None);
        // Pressed again: from where the cursor is now, not where it was.
        input.button(true);
        assert_eq!(input.moved(51.0, 50.0), Some((1.0, 0.0)));
    }

    #[test]
    fn keys_make_axes_and_losing_focus_releases_them() {
        let mut input = Input::default();
        input.key(KeyCode::KeyW, true);
        input.key(KeyCode::KeyD, true);
        input.key(KeyCode::ShiftLeft, true);
        input.key(KeyCode::KeyQ, true);
        assert_eq!(input.held(), Held { forward: 1, right: 1, up: -1, turn: 0, tilt: 0, boost: true });
        // Opposite keys cancel; a key let go stops.
        input.key(KeyCode::ArrowDown, true);
        input.key(KeyCode::KeyQ, false);
        assert_eq!(input.held(), Held { forward: 0, right: 1, up: 0, turn: 0, tilt: 0, boost: true });
        input.button(true);
        input.moved(1.0, 1.0);
        input.release_all();
        assert_eq!(input.held(), Held::default());
        assert_eq!(input.moved(2.0, 2.0), None);
    }
}
