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
//! A morph asked for while another runs or is still to come starts from
//! the level the track has when it begins: it cuts the one in progress
//! short there and replaces those that would begin later, so the level
//! never jumps, however the selections' times jitter. This gives the
//! **collapse rule**: if an upmorph was scheduled for an interval and the
//! next selection asks for a downmorph, which falls in (about) that same
//! interval, the two become one morph over it, from the level valid at its
//! beginning to the level required at its end.
//!
//! A jump of several levels morphs through them in turn within `τ` (001
//! §4.4): the level moves linearly, and at fractional level `λ` the mesh of
//! level `⌈λ⌉` is drawn with each vertex at
//! `h_{⌈λ⌉−1}(p) + (λ − ⌈λ⌉ + 1)(h_{⌈λ⌉}(p) − h_{⌈λ⌉−1}(p))`
//! ([`morphed_height`]), where `h_{l}(p)` is level `l`'s surface at the
//! vertex (bilinear between its samples). At an integer level the two
//! meshes describe the same surface, so switching meshes moves no vertex.
//!
//! Invariants: transitions are sorted by start and change the level; each
//! starts from the level the track has at its start, and lasts `τ` unless
//! the next one begins first and cuts it short.

/// One scheduled geomorph: the level goes linearly from `from` to `to`
/// over `[start_s, start_s + τ]`, or until the next transition begins.
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
    /// The level while no transition is scheduled.
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
        for (i, tr) in self.transitions.iter().enumerate() {
            if t_s <= tr.start_s {
                return tr.from;
            }
            if t_s < self.end_s(i) {
                return tr.from + (tr.to - tr.from) * ((t_s - tr.start_s) / self.tau_s);
            }
        }
        self.target()
    }

    /// The level the track ends at.
    pub fn target(&self) -> f64 {
        self.transitions.last().map_or(self.settled, |tr| tr.to)
    }

    /// When transition `i` ends: after `τ`, or where the next one begins.
    fn end_s(&self, i: usize) -> f64 {
        let end_s = self.transitions[i].start_s + self.tau_s;
        self.transitions.get(i + 1).map_or(end_s, |next| end_s.min(next.start_s))
    }

    /// A selection asks for `level` during `[target_s, target_s + τ)`: a
    /// downmorph over the interval before, an upmorph over that one.
    pub fn request(&mut self, level: u8, target_s: f64) {
        let want = f64::from(level);
        match want < self.level_at(target_s) {
            true => self.schedule(target_s - self.tau_s, want),
            false => self.schedule(target_s, want),
        }
    }

    /// A morph to `to` from `start_s`, from the level the track has then:
    /// what begins from `start_s` on is dropped, what runs then is cut short.
    fn schedule(&mut self, start_s: f64, to: f64) {
        let from = self.level_at(start_s);
        self.transitions.retain(|t| t.start_s < start_s);
        if from != to {
            self.transitions.push(Transition { start_s, from, to });
        }
    }

    /// Forgets transitions finished by `t_s`.
    pub fn prune(&mut self, t_s: f64) {
        while !self.transitions.is_empty() && self.end_s(0) <= t_s {
            self.settled = self.transitions.remove(0).to;
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
