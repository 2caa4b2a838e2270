//! Task messages on the work-queue stream: JSON `{"job", "kind"}` on
//! `rbfsurf.tasks.<kind>`, each published with the message id `<job>.<kind>[.<n>]`, so the
//! stream keeps one copy of a task published twice within its duplicate window (10 min).

use super::DistError;
use async_nats::jetstream::{self, message::PublishMessage};
use serde::{Deserialize, Serialize};
use uuid::Uuid;

/// What a task does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TaskKind {
    /// Read the input; run the whole job, or prepare the graph and publish its blocks.
    Start,
    /// Fit block `n`.
    Block(usize),
    /// Polygonize region `n`.
    Region(usize),
    /// Weld, post-process, store the results.
    Merge,
    /// Count byte range `n` of the input (the spread prepare, [`super::prepare`]).
    Survey(usize),
    /// Take the subsample's points of range `n`.
    Sample(usize),
    /// Route range `n` into the blocks' spills of the partition's generation `g`.
    Route(usize, u32),
    /// Make block `n`'s point set from its spill.
    CleanUp(usize),
    /// Run the whole job on one worker (a spread job the task graph refused).
    Whole,
}

/// One task.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Task {
    /// The job.
    pub job: Uuid,
    /// The step.
    pub kind: TaskKind,
}

impl Task {
    /// `start`, `block 3`, … for logs.
    pub fn label(&self) -> String {
        match self.kind {
            TaskKind::Start => "start".into(),
            TaskKind::Block(b) => format!("block {b}"),
            TaskKind::Region(r) => format!("region {r}"),
            TaskKind::Merge => "merge".into(),
            TaskKind::Survey(r) => format!("survey range {r}"),
            TaskKind::Sample(r) => format!("sample range {r}"),
            TaskKind::Route(r, g) => format!("route range {r} (generation {g})"),
            TaskKind::CleanUp(k) => format!("clean-up {k}"),
            TaskKind::Whole => "whole".into(),
        }
    }

    fn subject_and_id(&self) -> (String, String) {
        let (kind, n) = match self.kind {
            TaskKind::Start => ("start", None),
            TaskKind::Block(b) => ("block", Some(b.to_string())),
            TaskKind::Region(r) => ("region", Some(r.to_string())),
            TaskKind::Merge => ("merge", None),
            TaskKind::Survey(r) => ("survey", Some(r.to_string())),
            TaskKind::Sample(r) => ("sample", Some(r.to_string())),
            TaskKind::Route(r, g) => ("route", Some(format!("{g}.{r}"))),
            TaskKind::CleanUp(k) => ("cleanup", Some(k.to_string())),
            TaskKind::Whole => ("whole", None),
        };
        let id = match n {
            Some(n) => format!("{}.{kind}.{n}", self.job),
            None => format!("{}.{kind}", self.job),
        };
        (format!("rbfsurf.tasks.{kind}"), id)
    }
}

/// Publishes `tasks` (stored by the stream when this returns; duplicates dropped).
pub async fn publish(js: &jetstream::Context, tasks: &[Task]) -> Result<(), DistError> {
    for t in tasks {
        let (subject, id) = t.subject_and_id();
        let payload = serde_json::to_vec(t).unwrap_or_default();
        super::objects::retry(&format!("publish {subject}"), || async {
            let msg = PublishMessage::build()
                .payload(payload.clone().into())
                .message_id(&id);
            let ack = js
                .send_publish(subject.clone(), msg)
                .await
                .map_err(|e| (true, e.to_string()))?;
            ack.await.map(|_| ()).map_err(|e| (true, e.to_string()))
        })
        .await?;
    }
    Ok(())
}
