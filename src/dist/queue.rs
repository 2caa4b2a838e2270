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
        }
    }

    fn subject_and_id(&self) -> (String, String) {
        let (kind, n) = match self.kind {
            TaskKind::Start => ("start", None),
            TaskKind::Block(b) => ("block", Some(b)),
            TaskKind::Region(r) => ("region", Some(r)),
            TaskKind::Merge => ("merge", None),
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
