//! Geomorphing between tile levels (001 §3.4 and §4.4): a tile's level as a
//! continuous function of time, so vertices glide instead of popping.
//!
//! Selection runs asynchronously: the selection finished at time `t` is for
//! the target interval `[t + τ, t + 2τ)` (001's three-stage pipeline, with
//! `τ` also the morph duration). The two directions are not symmetric
//! because a morph costs what the finer level costs:
//! - a **downmorph** (to a coarser level) runs during the interval *before*
//!   the target, so the cheap level is in place when the target begins;
//! - an **upmorph** (to a finer level) runs *during* the target interval, so
//!   the expensive level is not drawn before its budget is granted.
//!
//! **Collapse rule**: if an upmorph was scheduled for an interval and the
//! next selection asks for a downmorph, which falls in that same interval,
//! the two become one morph over it, from the level valid at its beginning
//! to the level required at its end.
//!
//! A jump of several levels morphs through them in turn within `τ` (001
//! §4.4): the level moves linearly, and at fractional level `λ` the mesh of
//! level `⌈λ⌉` is drawn with each vertex at
//! `h_{⌈λ⌉−1}(p) + (λ − ⌈λ⌉ + 1)(h_{⌈λ⌉}(p) − h_{⌈λ⌉−1}(p))`
//! ([`morphed_height`]), where `h_{l}(p)` is level `l`'s surface at the
//! vertex (bilinear between its samples). At an integer level the two
//! meshes describe the same surface, so switching meshes moves no vertex.
//!
//! Invariants: transitions are sorted, do not overlap, each starts from the
//! level the previous one reached, and lasts exactly `τ`.

/// One scheduled geomorph: the level goes linearly from `from` to `to`
/// over `[start_s, start_s + τ]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Transition {
    /// Start, seconds.
    pub start_s: f64,
    /// Level at the start.
    pub from: f64,
    /// Level at the end.
    pub to: f64,
}

/// The level track of one tile (or one region of the terrain).
#[derive(Clone, Debug, PartialEq)]
pub struct MorphTrack {
    tau_s: f64,
    /// The level before the first transition.
    settled: f64,
    transitions: Vec<Transition>,
}

impl MorphTrack {
    /// A track resting at `level`, with morphs of `tau_s` seconds.
    pub fn new(level: u8, tau_s: f64) -> MorphTrack {
        let tau_s = if tau_s.is_finite() && tau_s > 0.0 { tau_s } else { f64::MIN_POSITIVE };
        MorphTrack { tau_s, settled: f64::from(level), transitions: Vec::new() }
    }

    /// The morph duration `τ`, seconds.
    pub fn tau_s(&self) -> f64 {
        self.tau_s
    }

    /// The scheduled transitions.
    pub fn transitions(&self) -> &[Transition] {
        &self.transitions
    }

    /// The (fractional) level at time `t_s`.
    pub fn level_at(&self, t_s: f64) -> f64 {
        let mut level = self.settled;
        for tr in &self.transitions {
            if t_s <= tr.start_s {
                return level;
            }
            if t_s < tr.start_s + self.tau_s {
                return tr.from + (tr.to - tr.from) * ((t_s - tr.start_s) / self.tau_s);
            }
            level = tr.to;
        }
        level
    }

    /// A selection asks for `level` during `[target_s, target_s + τ)`.
    pub fn request(&mut self, level: u8, target_s: f64) {
        let want = f64::from(level);
        let planned = self.level_at(target_s);
        if want < planned {
            self.downmorph(want, target_s - self.tau_s);
        } else if want > planned {
            self.schedule(Transition { start_s: target_s, from: planned, to: want });
        }
    }

    /// A downmorph over `[start_s, start_s + τ]`, collapsing with an
    /// upmorph already there.
    fn downmorph(&mut self, want: f64, start_s: f64) {
        let clash = self.transitions.iter().position(|tr| tr.start_s == start_s && tr.to > tr.from);
        match clash {
            Some(i) => {
                let from = self.transitions[i].from;
                self.transitions.truncate(i);
                if from != want {
                    self.transitions.push(Transition { start_s, from, to: want });
                }
            }
            None => {
                let from = self.level_at(start_s);
                self.schedule(Transition { start_s, from, to: want });
            }
        }
    }

    /// Appends `tr`, dropping anything scheduled from its start on.
    fn schedule(&mut self, tr: Transition) {
        self.transitions.retain(|t| t.start_s + self.tau_s <= tr.start_s);
        self.transitions.push(tr);
    }

    /// Forgets transitions finished by `t_s`.
    pub fn prune(&mut self, t_s: f64) {
        while let Some(tr) = self.transitions.first().copied().filter(|tr| tr.start_s + self.tau_s <= t_s) {
            self.settled = tr.to;
            self.transitions.remove(0);
        }
    }
}

/// The mesh to draw at fractional level `level` and its morph weight: the
/// mesh of level `⌈level⌉` with weight `level − ⌈level⌉ + 1 ∈ (0, 1]`
/// (an integer level draws its own mesh with weight 1).
pub fn mesh_and_weight(level: f64) -> (u8, f64) {
    let level = if level.is_nan() { 0.0 } else { level.clamp(0.0, 255.0) };
    let mesh = level.ceil();
    (mesh as u8, if mesh == 0.0 { 1.0 } else { level - mesh + 1.0 })
}

/// A morphing vertex's height: `coarse_m` (the coarser level's surface at
/// the vertex) moved toward `fine_m` (the vertex's own sample) by `weight`.
pub fn morphed_height(coarse_m: f64, fine_m: f64, weight: f64) -> f64 {
    coarse_m + weight.clamp(0.0, 1.0) * (fine_m - coarse_m)
}

#[cfg(test)]
#[path = "morph_tests.rs"]
mod tests;
