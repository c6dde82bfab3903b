//! LOD selection on its own thread (001 §4.1): the flight hands it a
//! [`Request`] (the predicted cameras, the conservative cone, the cost
//! model calibrated so far, the view-ray steps measured so far) and keeps drawing the last cut while it works.
//! At most one request is in flight; the thread ends when the worker is
//! dropped.

use super::super::camera::Camera;
use super::budget::{Budget, TreeItem};
use super::steps::RaySteps;
use super::{Selected, Selector};
use crate::grid::TileId;
use crate::lod::model::CostModel;
use crate::lod::predict::Cone;
use std::collections::HashSet;
use std::sync::Arc;
use std::sync::mpsc::{Receiver, Sender, TryRecvError, channel};
use std::thread::JoinHandle;

/// What to select for.
#[derive(Clone, Debug)]
pub struct Request {
    /// The cameras the cut is for.
    pub cameras: Vec<Camera>,
    /// The conservative camera, widening culling.
    pub cone: Option<Cone>,
    /// The tree groups near the camera.
    pub trees: Vec<TreeItem>,
    /// The cost model.
    pub model: CostModel,
    /// The budget.
    pub budget: Budget,
    /// The rays' fetches per tile.
    pub steps: Arc<RaySteps>,
    /// Under geomorphing, the cut drawn, whose refinements morph.
    pub refining: Option<Arc<HashSet<TileId>>>,
}

/// The selection thread and its channels.
pub struct Worker {
    requests: Option<Sender<Request>>,
    results: Receiver<Selected>,
    busy: bool,
    thread: Option<JoinHandle<()>>,
}

impl Worker {
    /// Starts the thread, which selects with `selector`.
    pub fn spawn(selector: Selector) -> std::io::Result<Worker> {
        let (requests, inbox) = channel::<Request>();
        let (outbox, results) = channel();
        let thread = std::thread::Builder::new().name("lod-select".into()).spawn(move || {
            for r in inbox {
                let pricing = (r.steps.as_ref(), r.refining.as_deref());
                let selected = selector.select(&r.cameras, r.cone, &r.trees, (&r.model, &r.budget), pricing);
                if outbox.send(selected).is_err() {
                    break;
                }
            }
        })?;
        Ok(Worker { requests: Some(requests), results, busy: false, thread: Some(thread) })
    }

    /// Whether a selection is in flight.
    pub fn busy(&self) -> bool {
        self.busy
    }

    /// Starts a selection unless one is in flight (or the thread is gone);
    /// whether it started.
    pub fn submit(&mut self, request: Request) -> bool {
        if self.busy {
            return false;
        }
        self.busy = self.requests.as_ref().is_some_and(|tx| tx.send(request).is_ok());
        self.busy
    }

    /// The selection finished since the last call, if any; with `wait`, the
    /// one in flight, waiting for it. `None` also when the thread is gone.
    pub fn take(&mut self, wait: bool) -> Option<Selected> {
        if !self.busy {
            return None;
        }
        let got = if wait {
            self.results.recv().ok()
        } else {
            match self.results.try_recv() {
                Ok(s) => Some(s),
                Err(TryRecvError::Empty) => return None,
                Err(TryRecvError::Disconnected) => None,
            }
        };
        self.busy = false;
        got
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        self.requests = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
