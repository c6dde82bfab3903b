//! A flight under a frame budget (issue 7, `lod` steps 1 and 6): every
//! frame the camera feeds the path predictor; every `τ` a selection for the
//! predicted cameras and the conservative cone is handed to the selection
//! thread ([`super::worker`]) while the last finished cut is drawn; after
//! each frame its features and measured time go to the calibrator (001
//! §4.2), so the next selection predicts with constants fitted to this GPU.
//! It also keeps the geomorphs of the cuts drawn ([`super::morphs`]).

use super::super::camera::Camera;
use super::ahead::{self, Lookahead, WINDOW};
use super::budget::{Budget, Choice};
use super::morphs::{Morphing, Morphs};
use super::worker::{Request, Worker};
use super::{Selected, Selector};
use crate::grid::TileId;
use crate::lod::calibrate::{CalibratorSettings, CostCalibrator};
use crate::lod::model::{CostFeatures, CostModel};
use crate::lod::predict::PathPredictor;

/// The calibrator's settings: a strong ridge toward the (freely scaled)
/// prior, since a flight's first frames differ little and software GPUs
/// time them with ±50 % noise (lavapipe on a shared machine); constants
/// separate only as frames keep disagreeing with the prior's proportions.
pub fn calibration() -> CalibratorSettings {
    CalibratorSettings { ridge: 0.03, ..CalibratorSettings::default() }
}

/// The selection state of a flight.
pub struct BudgetFlight {
    selector: Selector,
    calibrator: CostCalibrator,
    budget: Budget,
    look: Lookahead,
    predictor: PathPredictor,
    worker: Worker,
    /// The cut drawn now.
    current: Option<Selected>,
    /// Flight time of the last request.
    requested_s: f64,
    frames: usize,
    morphs: Morphs,
}

impl BudgetFlight {
    /// A flight of frames of `budget` looking ahead by `look`, starting
    /// from the default cost model.
    pub fn new(selector: Selector, budget: Budget, look: Lookahead) -> std::io::Result<BudgetFlight> {
        Ok(BudgetFlight {
            worker: Worker::spawn(selector.clone())?,
            selector,
            calibrator: CostCalibrator::new(CostModel::default(), calibration()),
            budget,
            look,
            predictor: PathPredictor::new(WINDOW),
            current: None,
            requested_s: f64::NEG_INFINITY,
            frames: 0,
            morphs: Morphs::new(look.tau_s),
        })
    }

    /// The cost model now.
    pub fn model(&self) -> CostModel {
        self.calibrator.model()
    }

    /// The budget.
    pub fn budget(&self) -> &Budget {
        &self.budget
    }

    /// The cut to draw at flight time `t_s` from `camera`: the newest
    /// finished selection (waiting only for the first). Starts the next
    /// selection when `τ` has passed since the last and the thread is idle.
    pub fn frame(&mut self, t_s: f64, camera: &Camera) -> Selected {
        self.predictor.observe(t_s, ahead::pose(camera));
        if let Some(done) = self.worker.take(false) {
            self.current = Some(done);
        }
        if !self.worker.busy() && t_s >= self.requested_s + self.look.tau_s {
            let (cameras, cone) = ahead::ahead(&self.predictor, camera, t_s, &self.look);
            let request = Request { cameras, cone: Some(cone), model: self.model(), budget: self.budget };
            if self.worker.submit(request) {
                self.requested_s = t_s;
            }
        }
        if self.current.is_none() {
            self.current = self.worker.take(true);
        }
        let model = self.model();
        self.current
            .get_or_insert_with(|| self.selector.select(std::slice::from_ref(camera), None, &model, &self.budget))
            .clone()
    }

    /// Which tiles of `drawn`, the cut drawn at `t_s`, morph from a
    /// coarser tile (over `τ`).
    pub fn morphs(&mut self, t_s: f64, drawn: &[TileId]) -> Vec<Morphing> {
        self.morphs.update(t_s, drawn)
    }

    /// Records a drawn frame: its tiles as drawn from `camera` and its
    /// measured time. Returns the frame's features, priced by the model
    /// before this frame's correction. The first frame builds the GPU
    /// pipelines and is not calibrated.
    pub fn observe(&mut self, camera: &Camera, drawn: &[Choice], measured_ms: f64) -> CostFeatures {
        let features = self.selector.features(camera, drawn);
        if self.frames > 0 {
            self.calibrator.observe(&features, measured_ms);
        }
        self.frames += 1;
        features
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::client::globe::Geodetic;
    use crate::client::store::Knowledge;
    use crate::grid::{BBox, TileGrid};
    use crate::lod::predict::MotionLimits;

    fn flight() -> BudgetFlight {
        let selector = Selector {
            grid: TileGrid::new(36.0, 513).unwrap(),
            bounds: BBox { west: 10.0, south: 46.3, east: 10.25, north: 46.45 },
            knowledge: Knowledge::default(),
            fade: (30.0, 0.5, 2.0),
            max_level: 14,
        };
        let budget = Budget { budget_ms: 8.0, max_tiles: 256, shadows: true, deadline: None };
        let look = Lookahead { tau_s: 1.0, limits: MotionLimits { max_speed_mps: 100.0, max_turn_radps: 0.1 } };
        BudgetFlight::new(selector, budget, look).unwrap()
    }

    fn camera(lon: f64) -> Camera {
        Camera::looking(Geodetic::new(lon, 46.33, 2000.0), 0.0, -20.0, 60.0, (160, 120))
    }

    fn ids(s: &Selected) -> Vec<crate::grid::TileId> {
        s.cut.tiles.iter().map(|c| c.id).collect()
    }

    #[test]
    fn the_last_cut_is_drawn_while_the_thread_selects_the_next() {
        let mut f = flight();
        let first = f.frame(0.0, &camera(10.05));
        assert!(!first.cut.tiles.is_empty() && first.cut.predicted_ms <= 8.0, "{:?}", first.cut);
        // A little east a second later: the cut for the first view is still drawn
        // while the thread selects for the new one.
        let second = f.frame(1.0, &camera(10.08));
        assert_eq!(ids(&second), ids(&first));
        // It arrives within a few frames (within τ, none is started anew).
        let adopted = (0..200).find_map(|_| {
            std::thread::sleep(std::time::Duration::from_millis(10));
            let s = f.frame(1.5, &camera(10.08));
            (ids(&s) != ids(&first)).then_some(s)
        });
        assert!(adopted.is_some(), "the new cut was adopted");
    }

    #[test]
    fn a_selection_is_started_once_per_tau() {
        let mut f = flight();
        f.frame(0.0, &camera(10.05));
        // Half of τ later nothing new is started; a whole τ later it is.
        f.frame(0.5, &camera(10.06));
        assert!(!f.worker.busy() && f.requested_s == 0.0);
        f.frame(1.0, &camera(10.07));
        assert_eq!(f.requested_s, 1.0);
    }

    #[test]
    fn measured_frames_calibrate_the_model() {
        let mut f = flight();
        let cam = camera(10.05);
        let cut = f.frame(0.0, &cam).cut;
        let before = f.model().predict_ms(&f.selector.features(&cam, &cut.tiles));
        // The first frame builds pipelines and teaches nothing.
        f.observe(&cam, &cut.tiles, 1000.0);
        assert_eq!(f.model(), CostModel::default());
        for _ in 0..5 {
            f.observe(&cam, &cut.tiles, 4.0 * before);
        }
        let after = f.model().predict_ms(&f.selector.features(&cam, &cut.tiles));
        assert!((after / (4.0 * before) - 1.0).abs() < 0.05, "{before} → {after}");
    }
}
