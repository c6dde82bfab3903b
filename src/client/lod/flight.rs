//! A flight under a frame budget (issue 7, `lod` steps 1 and 6): every
//! frame the camera feeds the path predictor; every `τ` a selection for the
//! predicted cameras and the conservative cone is handed to the selection
//! thread ([`super::worker`]) with the tree groups near those cameras
//! (grown on the tiles last drawn) while the last finished cut is drawn,
//! its budget's remainder given to tree groups its selection did not see;
//! after each frame its features and measured time go to the calibrator
//! (001 §4.2), so the next selection predicts with constants fitted to this
//! GPU, and its rays' fetches per tile to [`super::steps`], so the next
//! selection prices each tile's rays as they were last measured.
//! With geomorphing on it also keeps the morphs of the cuts drawn
//! ([`super::morphs`]).

use super::super::camera::Camera;
use super::super::tile::TileData;
use super::super::trees;
use super::ahead::{self, Lookahead, WINDOW};
use super::budget::{self, Budget, Choice, TreeItem};
use super::morphs::{Morphing, Morphs, Pairs};
use super::steps::{FrameSteps, RaySteps, VIEW_STEPS};
use super::worker::{Request, Worker};
use super::{Selected, Selector};
use crate::grid::{TileGrid, TileId};
use crate::lod::calibrate::{CalibratorSettings, CostCalibrator};
use crate::lod::model::{CostFeatures, CostModel};
use crate::lod::predict::PathPredictor;
use std::collections::HashSet;
use std::sync::Arc;

/// The calibrator's settings: a light ridge toward the (freely scaled)
/// prior, and a floor under the ridge of features seen rarely (tree groups
/// now and then), so that they keep the prior's proportions. The ridge was
/// 0.03, set for lavapipe's unheld frame times (±50 % noise); with frame
/// times that follow the work (`fly --hold-ms`) the model fits the frames
/// better at 0.001 (`docs/benchmarks.md`, "What limits budget control").
/// The floor times the ridge is what it was (0.03 × 0.01): trees are
/// guarded as before.
pub fn calibration() -> CalibratorSettings {
    CalibratorSettings { ridge: 1e-3, ridge_floor: RIDGE_FLOOR, ..CalibratorSettings::default() }
}

/// The calibrator's ridge floor (see [`CalibratorSettings::ridge_floor`]).
pub const RIDGE_FLOOR: f64 = 0.3;

/// The selection state of a flight.
pub struct BudgetFlight {
    selector: Selector,
    calibrator: CostCalibrator,
    budget: Budget,
    /// View- and shadow-ray fetches per tile, as last measured (shared with
    /// the request in flight; copied on write).
    steps: Arc<RaySteps>,
    look: Lookahead,
    predictor: PathPredictor,
    worker: Worker,
    /// The cut drawn now.
    current: Option<Selected>,
    /// A cut held while the morphs it would break run: drawn once the
    /// tiles it coarsens have morphed onto its coarser tiles and those it
    /// refines have stopped morphing, or [`MAX_HOLD`] periods after a cut
    /// was first held (newer selections replace it and start morphs anew).
    pending: Option<Selected>,
    /// Flight time a cut was first held since the last one was drawn.
    held_s: f64,
    /// Flight time of the last request.
    requested_s: f64,
    frames: usize,
    /// The morphs, with geomorphing on, and the tiles they draw.
    morphs: Option<Morphs>,
    pairs: Pairs,
    /// The tiles last drawn, on which the selector's trees grow.
    drawn: Vec<Arc<TileData>>,
    /// The current cut as this frame draws it: with the tree groups its
    /// selection did not see priced (see [`Self::price_trees`]).
    priced: Option<Selected>,
    /// What the frames drawn cost over what their selections predicted,
    /// both priced by the model now (a moving average): selections price
    /// the cameras ahead and the conservative cone, which see more than
    /// the camera that draws, so they aim at the budget over this.
    aim: f64,
}

/// Weight of a frame in [`BudgetFlight`]'s moving average of drawn over
/// selected cost.
const AIM_WEIGHT: f64 = 0.25;
/// The aim stays within this factor of 1 (either way).
const AIM_LIMIT: f64 = 2.0;

impl BudgetFlight {
    /// A flight of frames of `budget` looking ahead by `look`, starting
    /// from the cost model `prior` (and [`VIEW_STEPS`] steps per pixel),
    /// geomorphing or not.
    pub fn new(
        selector: Selector,
        budget: Budget,
        look: Lookahead,
        prior: CostModel,
        geomorph: bool,
    ) -> std::io::Result<BudgetFlight> {
        Ok(BudgetFlight {
            worker: Worker::spawn(selector.clone())?,
            selector,
            calibrator: CostCalibrator::new(prior, calibration()),
            budget,
            steps: Arc::new(RaySteps::new(VIEW_STEPS)),
            look,
            predictor: PathPredictor::new(WINDOW),
            current: None,
            pending: None,
            held_s: 0.0,
            requested_s: f64::NEG_INFINITY,
            frames: 0,
            morphs: geomorph.then(|| Morphs::new(look.tau_s)),
            pairs: Pairs::default(),
            drawn: Vec::new(),
            priced: None,
            aim: 1.0,
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

    /// Looks ahead by `look` from the next selection on, pricing shadow
    /// rays or not (an interactive camera's speed, frame time and sun
    /// change; geomorphs keep the period they started with).
    pub fn set_motion(&mut self, look: Lookahead, shadows: bool) {
        self.look = look;
        self.budget.shadows = shadows;
    }

    /// The rays' fetches the next selection prices tiles with.
    pub fn steps(&self) -> &RaySteps {
        &self.steps
    }

    /// The cut to draw at flight time `t_s` from `camera`: the newest
    /// finished selection (waiting only for the first). Starts the next
    /// selection when `τ` has passed since the last and the thread is idle.
    pub fn frame(&mut self, t_s: f64, camera: &Camera) -> Selected {
        self.priced = None;
        self.predictor.observe(t_s, ahead::pose(camera));
        // A selection looks τ ahead of its request: a frame later than that
        // (frames farther apart than τ) is past the views the cut in hand
        // was made for, and waits for one made now.
        // Half a period of slack: the frame that starts the next request
        // comes about τ after the last one, a little more or less.
        let tau = self.look.tau_s;
        let stale = t_s > self.requested_s + STALE_PERIODS * tau;
        let held_too_long = t_s >= self.held_s + MAX_HOLD * tau;
        if (held_too_long || self.morphs.as_ref().is_none_or(Morphs::settled))
            && let Some(p) = self.pending.take()
        {
            self.current = Some(p);
        }
        if let Some(done) = self.worker.take(stale) {
            self.offer(done, t_s);
        }
        if !self.worker.busy() && t_s >= self.requested_s + self.look.tau_s {
            let ground = |lon, lat| self.selector.lowest_ground_m(lon, lat);
            let (cameras, cone) =
                ahead::ahead(&self.predictor, camera, t_s, ahead::stages(self.morphs.is_some()), &self.look, &ground);
            let trees = self.tree_items(&cameras);
            let (model, budget, steps) = (self.model(), self.aimed(), self.steps.clone());
            let refining = self.refining().map(Arc::new);
            let request = Request { cameras, cone: Some(cone), trees, model, budget, steps, refining };
            if self.worker.submit(request) {
                self.requested_s = t_s;
            }
        }
        // Drawn at once: no morph bridges views that far apart.
        if stale && let Some(done) = self.worker.take(true) {
            (self.current, self.pending) = (Some(done), None);
        }
        if self.current.is_none() {
            self.current = self.worker.take(true);
        }
        let model = self.model();
        if self.current.is_none() {
            let cameras = std::slice::from_ref(camera);
            let trees = self.tree_items(cameras);
            let refining = self.refining();
            let pricing = (self.steps.as_ref(), refining.as_ref());
            self.current = Some(self.selector.select(cameras, None, &trees, (&model, &self.budget), pricing));
        }
        self.current.clone().unwrap_or_default()
    }

    /// Under geomorphing, the cut a selection started now replaces (the
    /// held one, else the one drawn): its refinements will morph.
    fn refining(&self) -> Option<HashSet<TileId>> {
        self.morphs.as_ref()?;
        Some(self.pending.as_ref().or(self.current.as_ref()).map_or_else(Vec::new, ids).into_iter().collect())
    }

    /// The tiles drawn, on which the next selections' tree groups grow.
    pub fn set_drawn(&mut self, drawn: Vec<Arc<TileData>>) {
        self.drawn = drawn;
    }

    /// The cut drawn now as this frame draws it: its splat budgets
    /// extended to the tree groups `groups` of the frame drawn from
    /// `camera` on `tiles` that its selection did not price
    /// ([`budget::price_unseen_trees`], under the budget aimed at; each
    /// frame anew, so groups passed by leave the budget); `None` before the
    /// first [`Self::frame`].
    pub fn price_trees(
        &mut self,
        camera: &Camera,
        tiles: &[&TileData],
        groups: &[trees::TreeGroup],
    ) -> Option<Selected> {
        let (budget, model) = (self.aimed(), self.model());
        let field = self.selector.trees.as_ref()?.field;
        let mut priced = self.current.clone()?;
        // All the frame's groups share the screen, those priced included.
        let items: Vec<TreeItem> = groups.iter().map(|g| g.item(tiles, &field, camera.focal_px())).collect();
        let px = super::trees_px(std::slice::from_ref(camera), &items);
        let unseen: Vec<(TreeItem, f64)> =
            items.into_iter().zip(px).filter(|(t, _)| !priced.cut.tree_budgets.contains_key(&t.block)).collect();
        if !unseen.is_empty() {
            budget::price_unseen_trees(&mut priced.cut, &unseen, &model, budget.budget_ms);
        }
        self.priced = Some(priced.clone());
        Some(priced)
    }

    /// The tree groups near `cameras` on the tiles last drawn, each once,
    /// with the share of the cameras it is near.
    fn tree_items(&self, cameras: &[Camera]) -> Vec<TreeItem> {
        let Some(settings) = &self.selector.trees else { return Vec::new() };
        let refs: Vec<&TileData> = self.drawn.iter().map(|t| t.as_ref()).collect();
        let mut items: Vec<TreeItem> = Vec::new();
        let per_camera = 1.0 / cameras.len().max(1) as f64;
        for camera in cameras {
            let blend = settings.blend(camera.focal_px());
            for g in trees::groups_near(settings, &refs, camera, &blend) {
                match items.iter_mut().find(|i| i.block == g.block) {
                    Some(item) => item.share += per_camera,
                    None => {
                        items.push(TreeItem { share: per_camera, ..g.item(&refs, &settings.field, camera.focal_px()) })
                    }
                }
            }
        }
        items
    }

    /// Which tiles of `drawn`, the cut drawn at `t_s`, morph from or to a
    /// coarser tile (over `τ`); the frame's [`Self::morph_tile`]s follow.
    pub fn morphs(&mut self, t_s: f64, drawn: &[TileId]) -> Vec<Morphing> {
        self.pairs.next_frame();
        let next: Option<Vec<TileId>> = self.pending.as_ref().map(ids);
        let Some(morphs) = &mut self.morphs else { return Vec::new() };
        morphs.update(t_s, drawn, next.as_deref())
    }

    /// The tiles to draw for `cut`: as selected, but tiles under a drawn
    /// tile still morphing wait for its morph ([`Morphs::hold_under_morphing`]).
    pub fn held_cut(&self, cut: &[TileId]) -> Vec<TileId> {
        match &self.morphs {
            Some(m) => m.hold_under_morphing(cut),
            None => cut.to_vec(),
        }
    }

    /// `tile` prepared to be drawn morphing with `from`, kept while the
    /// morph lasts.
    pub fn morph_tile(&mut self, grid: &TileGrid, tile: &TileData, from: &TileData) -> Arc<TileData> {
        self.pairs.get(grid, tile, from)
    }

    /// A finished selection: drawn at once unless, geomorphing, it
    /// coarsens the cut drawn or refines a tile still morphing: then it is
    /// held while the tiles it replaces morph down, or finish morphing (a
    /// newer one replaces it there; [`Morphs`] sends back up the tiles it
    /// no longer coarsens).
    fn offer(&mut self, next: Selected, t_s: f64) {
        let Some(current) = &self.current else {
            self.current = Some(next);
            return;
        };
        if let Some(p) = &mut self.pending {
            *p = next;
        } else if let Some(m) = &self.morphs
            && (coarsens(current, &next) || m.refines_morphing(&ids(&next)))
        {
            self.pending = Some(next);
            self.held_s = t_s;
        } else {
            self.current = Some(next);
        }
    }

    /// Records a drawn frame: its tiles as drawn from `camera`, its
    /// trees, its measured time and view-ray steps per
    /// ray-cast pixel (which the next selections price tiles with).
    /// Returns the frame's features and what the model, before this
    /// frame's correction, predicts for them. The first frame builds the
    /// GPU pipelines and is not calibrated.
    pub fn observe(
        &mut self,
        camera: &Camera,
        drawn: &[Choice],
        trees: &trees::Drawn,
        (measured_ms, steps): (f64, &FrameSteps),
    ) -> Observed {
        Arc::make_mut(&mut self.steps).record(steps);
        let splats = budget::tree_features(trees.splats as f64, trees.groups as f64, trees.fill_px);
        let features = self.selector.features(camera, drawn, &self.steps).plus(&splats);
        let model_ms = self.model().predict_ms(&features);
        if self.frames > 0 {
            self.follow_aim(&features);
            self.calibrator.observe(&features, measured_ms);
        }
        self.frames += 1;
        Observed { features, model_ms }
    }

    /// The budget the selections aim at: the frame budget over the aim.
    fn aimed(&self) -> Budget {
        Budget { budget_ms: self.budget.budget_ms / self.aim, ..self.budget }
    }

    /// What a frame drawing `selected` is expected to cost: its
    /// prediction times the aim.
    pub fn expected_ms(&self, selected: &Selected) -> f64 {
        selected.cut.predicted_ms * self.aim
    }

    /// Moves the aim toward what the frame drawn with `features` costs
    /// over what its selection predicted, both priced by the model now.
    fn follow_aim(&mut self, features: &CostFeatures) {
        let Some(selected) = self.priced.as_ref().or(self.current.as_ref()) else { return };
        let model = self.model();
        let ratio = model.predict_ms(features) / model.predict_ms(&selected.cut.features);
        if ratio.is_finite() && ratio > 0.0 {
            let aim = (1.0 - AIM_WEIGHT) * self.aim + AIM_WEIGHT * ratio;
            self.aim = aim.clamp(1.0 / AIM_LIMIT, AIM_LIMIT);
        }
    }
}

/// A drawn frame as the cost model sees it.
#[derive(Clone, Copy, Debug)]
pub struct Observed {
    /// What the frame drew.
    pub features: CostFeatures,
    /// The model's prediction for it, before the frame corrected the model.
    pub model_ms: f64,
}

/// Periods after the last request past which a frame is stale: its views
/// are past those the cut in hand was selected for, and it waits for a cut
/// selected for it.
const STALE_PERIODS: f64 = 1.5;

/// Periods a cut is held at most for the morphs it would break: the newer
/// selections that replace it start morphs of their own, and without a
/// limit a flight that keeps coarsening would draw the old, finer cut (over
/// the budget) for good. At the limit the held cut is drawn, its morphs
/// cut short.
const MAX_HOLD: f64 = 2.0;

fn ids(s: &Selected) -> Vec<TileId> {
    s.cut.tiles.iter().map(|c| c.id).collect()
}

/// Whether `next` draws a strict ancestor of a tile `current` draws.
fn coarsens(current: &Selected, next: &Selected) -> bool {
    let next: std::collections::HashSet<TileId> = ids(next).into_iter().collect();
    ids(current).into_iter().any(|id| std::iter::successors(id.parent(), |p| p.parent()).any(|a| next.contains(&a)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::client::globe::Geodetic;
    use crate::client::lod::steps::Means;
    use crate::client::store::Knowledge;
    use crate::grid::{BBox, TileGrid};
    use crate::lod::predict::MotionLimits;

    fn flight() -> BudgetFlight {
        let selector = Selector {
            grid: TileGrid::new(36.0, 513).unwrap(),
            bounds: BBox { west: 10.0, south: 46.3, east: 10.25, north: 46.45 },
            knowledge: Knowledge::default(),
            fade: (30.0, 0.5, 2.0),
            trees: None,
            max_level: 14,
        };
        let budget = Budget { budget_ms: 8.0, max_tiles: 256, shadows: true, time_limit: None };
        let look = Lookahead { tau_s: 1.0, limits: MotionLimits { max_speed_mps: 100.0, max_turn_radps: 0.1 } };
        BudgetFlight::new(selector, budget, look, CostModel::default(), true).unwrap()
    }

    fn camera(lon: f64) -> Camera {
        Camera::looking(Geodetic::new(lon, 46.33, 2000.0), 0.0, -20.0, 60.0, (160, 120))
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
    fn a_frame_past_the_selections_horizon_waits_for_its_own() {
        // Regression: a flight of frames far apart drew each frame with the
        // cut selected for the frame before, tens of seconds earlier.
        let mut f = flight();
        let first = f.frame(0.0, &camera(10.05));
        let later = f.frame(30.0, &camera(10.2));
        assert_ne!(ids(&later), ids(&first), "the cut for the view 30 s later");
        assert!(!f.worker.busy() && f.requested_s == 30.0);
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

    /// `s` with its `k`th tile replaced by its children (last).
    fn refined(s: &Selected, k: usize) -> Selected {
        let mut s = s.clone();
        let tile = s.cut.tiles.remove(k);
        s.cut.tiles.extend(tile.id.children().map(|id| Choice { id, ..tile }));
        s
    }

    #[test]
    fn a_cut_refining_a_tile_still_morphing_is_held() {
        let mut f = flight();
        let first = f.frame(0.0, &camera(10.05));
        f.morphs(0.0, &ids(&first));
        let finer = refined(&first, 0);
        f.offer(finer.clone(), 0.0);
        assert!(f.pending.is_none(), "nothing morphs: drawn at once");
        f.morphs(0.1, &ids(&finer));
        // A child of the tile refined, morphing up from it, refined again.
        let held = refined(&finer, finer.cut.tiles.len() - 1);
        f.offer(held.clone(), 0.1);
        assert!(f.pending.is_some(), "held while its parent morphs");
        // Held for at most two periods (regression: newer selections
        // replacing it could hold the old cut for good).
        f.morphs(0.5, &ids(&finer));
        f.requested_s = 1.0;
        assert_eq!(ids(&f.frame(1.0, &camera(10.05))), ids(&finer), "still held");
        f.requested_s = 2.0;
        assert_eq!(ids(&f.frame(2.1, &camera(10.05))), ids(&held), "drawn at the limit");
    }

    #[test]
    fn selections_price_the_refinements_of_the_cut_they_replace_as_morph_pairs() {
        let mut f = flight();
        let first = f.frame(0.0, &camera(10.05));
        assert!(first.cut.tiles.iter().all(|c| !c.morphs), "nothing drawn before: {:?}", first.cut.tiles);
        // Lower, a period later: the next cut refines the first. Its
        // request starts before the first is drawn (no `morphs` call):
        // judged against the cut the morphs last saw drawn (review), none
        // of its tiles was priced as morphing.
        let low = Camera::looking(Geodetic::new(10.05, 46.33, 1200.0), 0.0, -20.0, 60.0, (160, 120));
        let next = (0..500).find_map(|_| {
            std::thread::sleep(std::time::Duration::from_millis(10));
            let s = f.frame(1.0, &low);
            (ids(&s) != ids(&first)).then_some(s)
        });
        let next = next.expect("a new cut");
        let drawn: HashSet<TileId> = ids(&first).into_iter().collect();
        let below = |id: TileId| std::iter::successors(id.parent(), TileId::parent).any(|a| drawn.contains(&a));
        assert!(next.cut.tiles.iter().all(|c| c.morphs == below(c.id)), "{:?}", next.cut.tiles);
        assert!(next.cut.tiles.iter().any(|c| c.morphs), "it refines: {:?}", next.cut.tiles);
    }

    #[test]
    fn the_frame_that_starts_a_selection_does_not_wait_for_it() {
        // Regression: a frame a hair over τ after the last request (float
        // times of frames τ apart) was taken for a stale one and waited for
        // the selection it had just started, every other frame or so.
        let mut f = flight();
        f.frame(0.0, &camera(10.05));
        f.frame(1.0 + 1e-9, &camera(10.06));
        assert!(f.worker.busy() && f.requested_s == 1.0 + 1e-9);
    }

    /// A frame whose every pixel took `steps` view-ray steps.
    fn even(steps: f64) -> FrameSteps {
        FrameSteps { view: Means { mean: Some(steps), tiles: Vec::new() }, ..FrameSteps::default() }
    }

    #[test]
    fn measured_frames_calibrate_the_model() {
        let mut f = flight();
        let cam = camera(10.05);
        let cut = f.frame(0.0, &cam).cut;
        let at_20 = RaySteps::new(20.0);
        let before = f.model().predict_ms(&f.selector.features(&cam, &cut.tiles, &at_20));
        // The first frame builds pipelines and teaches nothing.
        f.observe(&cam, &cut.tiles, &trees::Drawn::default(), (1000.0, &even(20.0)));
        assert_eq!(f.model(), CostModel::default());
        for _ in 0..5 {
            f.observe(&cam, &cut.tiles, &trees::Drawn::default(), (4.0 * before, &even(20.0)));
        }
        let after = f.model().predict_ms(&f.selector.features(&cam, &cut.tiles, &at_20));
        assert!((after / (4.0 * before) - 1.0).abs() < 0.05, "{before} → {after}");
    }

    #[test]
    fn selections_price_each_tiles_rays_with_the_fetches_last_measured_on_it() {
        let mut f = flight();
        let cam = camera(10.05);
        let mut tiles = f.frame(0.0, &cam).cut.tiles;
        assert!(tiles.len() > 1);
        assert_eq!(f.steps().view(tiles[0].id, false), VIEW_STEPS, "before any frame");
        // Ray pixels: priced at 10⁶ steps, a tile costs its pixels in Mpx·steps.
        let px = |tiles: &[Choice]| f.selector.features(&cam, tiles, &RaySteps::new(1e6)).raycast_mpx_steps;
        tiles.sort_by(|a, b| px(&[*b]).total_cmp(&px(&[*a])));
        tiles.iter_mut().for_each(|c| c.shadow_steps = 10);
        let (first, rest) = (px(&tiles[..1]), px(&tiles[1..]));
        assert!(first > 0.0 && rest > 0.0);
        // The largest tile's view rays took 35 steps a pixel, the frame's
        // 12; its shadow rays 1.6 fetches a step, the frame's 0.5.
        let measured = FrameSteps {
            view: Means { mean: Some(12.0), tiles: vec![(tiles[0].id, 35.0)] },
            shadow: Means { mean: Some(0.5), tiles: vec![(tiles[0].id, 1.6)] },
            pairs: Vec::new(),
        };
        let features = f.observe(&cam, &tiles, &trees::Drawn::default(), (50.0, &measured)).features;
        let expected = (first * 35.0 + rest * 12.0) / 1e6;
        assert!((features.raycast_mpx_steps / expected - 1.0).abs() < 1e-9, "{features:?} against {expected}");
        let expected = (first * 1.6 + rest * 0.5) * 10.0 / 1e6;
        assert!((features.shadow_mpx_steps / expected - 1.0).abs() < 1e-9, "{features:?} against {expected}");
        assert_eq!((f.steps().view(tiles[0].id, false), f.steps().view(tiles[1].id, false)), (35.0, 12.0));
        assert_eq!((f.steps().shadow(tiles[0].id, false), f.steps().shadow(tiles[1].id, false)), (1.6, 0.5));
    }

    #[test]
    fn selections_aim_past_the_budget_when_frames_draw_less_than_predicted() {
        let mut f = flight();
        let cam = camera(10.05);
        let cut = f.frame(0.0, &cam).cut;
        let steps = f.steps().clone();
        // Frames measured as the model prices them, so it stays.
        let draw = |f: &mut BudgetFlight, tiles: &[Choice]| {
            let ms = f.model().predict_ms(&f.selector.features(&cam, tiles, &steps));
            f.observe(&cam, tiles, &trees::Drawn::default(), (ms, &even(steps.view_mean())));
        };
        // Frames drawing what their selection priced: the aim stays.
        for _ in 0..3 {
            draw(&mut f, &cut.tiles);
        }
        assert!((f.aimed().budget_ms - 8.0).abs() < 1e-9, "{}", f.aimed().budget_ms);
        // Frames drawing fewer tiles cost less: later selections aim higher.
        let fewer = &cut.tiles[..cut.tiles.len() * 7 / 8];
        for _ in 0..20 {
            draw(&mut f, fewer);
        }
        let model = f.model();
        let ratio = model.predict_ms(&f.selector.features(&cam, fewer, &steps)) / model.predict_ms(&cut.features);
        assert!(ratio < 0.98 && ratio > 1.0 / AIM_LIMIT && (f.aim / ratio - 1.0).abs() < 0.01, "{ratio} {}", f.aim);
        assert!((f.aimed().budget_ms - 8.0 / f.aim).abs() < 1e-9);
        let expected = f.expected_ms(&f.current.clone().unwrap());
        assert!((expected - cut.predicted_ms * f.aim).abs() < 1e-9);
    }
}
