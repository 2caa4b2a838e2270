//! Lingering close: a request answered before its body was read (a refusal from the headers or
//! the query: 401, 400, 413, 415, 422, 429, …) still gets its answer to clients that send the
//! whole body before they read (Python's `urllib`, `requests`).
//!
//! Closing a socket with unread bytes in its receive buffer makes the kernel reset the
//! connection; such a client is still writing the body, gets `EPIPE`/`ECONNRESET` and never reads
//! the answer. So the body of every request is wrapped: when the handler drops it unfinished, a
//! separate task keeps reading and discarding it (hyper writes the answer meanwhile), at most
//! [`Linger::max_bytes`] bytes and [`Linger::max_time`], then drops it, and the connection
//! closes. The answer carries `Connection: close`. The drain holds no upload slot and no worker;
//! a slow or endless body costs one idle task for at most `max_time`.
//!
//! `Expect: 100-continue`: the body is not read when the handler did not ask for it, so hyper
//! never sends `100 Continue`; the client gets the refusal instead and sends no body.

use axum::body::{Body, Bytes, HttpBody};
use axum::extract::Request;
use axum::http::{HeaderValue, header};
use axum::middleware::Next;
use axum::response::Response;
use futures_util::StreamExt;
use hyper::body::{Frame, SizeHint};
use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::task::{Context, Poll};
use std::time::Duration;

/// Bounds of the drain after an early answer.
#[derive(Debug, Clone, Copy)]
pub struct Linger {
    /// Most bytes read and discarded, counted from the start of the body (a body declared
    /// larger by its `Content-Length` is not drained: the connection closes after the answer).
    pub max_bytes: u64,
    /// Longest drain, from the moment the handler dropped the body.
    pub max_time: Duration,
}

/// What the handler did with the body (shared with the middleware, which reads it after).
#[derive(Debug, Default)]
struct Seen {
    /// The handler polled the body (hyper then sent `100 Continue` when asked for it).
    polled: AtomicBool,
    /// The body was read to its end.
    ended: AtomicBool,
}

/// A request body that drains itself after an early answer (see the module documentation).
struct Lingering {
    inner: Option<Body>,
    seen: Arc<Seen>,
    /// The client sent `Expect: 100-continue`.
    expects_continue: bool,
    /// Bytes already handed to the handler.
    read: u64,
    /// `Content-Length`, when declared.
    declared: Option<u64>,
    bounds: Linger,
}

impl HttpBody for Lingering {
    type Data = Bytes;
    type Error = axum::Error;

    fn poll_frame(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<Frame<Bytes>, axum::Error>>> {
        let this = &mut *self;
        let Some(inner) = this.inner.as_mut() else {
            return Poll::Ready(None);
        };
        this.seen.polled.store(true, Ordering::Relaxed);
        let poll = Pin::new(&mut *inner).poll_frame(cx);
        match &poll {
            Poll::Ready(None) => this.seen.ended.store(true, Ordering::Relaxed),
            Poll::Ready(Some(Ok(frame))) => {
                if let Some(data) = frame.data_ref() {
                    this.read += data.len() as u64;
                }
                if inner.is_end_stream() {
                    this.seen.ended.store(true, Ordering::Relaxed);
                }
            }
            _ => {}
        }
        poll
    }

    fn is_end_stream(&self) -> bool {
        self.inner.as_ref().is_none_or(HttpBody::is_end_stream)
    }

    fn size_hint(&self) -> SizeHint {
        self.inner
            .as_ref()
            .map_or_else(|| SizeHint::with_exact(0), HttpBody::size_hint)
    }
}

impl Drop for Lingering {
    fn drop(&mut self) {
        let Some(body) = self.inner.take() else {
            return;
        };
        let unread = !self.seen.ended.load(Ordering::Relaxed) && !body.is_end_stream();
        let asked = self.seen.polled.load(Ordering::Relaxed) || !self.expects_continue;
        let fits = self.declared.is_none_or(|n| n <= self.bounds.max_bytes);
        if !(unread && asked && fits) {
            return;
        }
        let budget = self.bounds.max_bytes.saturating_sub(self.read);
        let time = self.bounds.max_time;
        if let Ok(rt) = tokio::runtime::Handle::try_current() {
            rt.spawn(drain(body, budget, time));
        }
    }
}

/// Reads and discards `body` until it ends, errs, passes `budget` bytes or `time` passes.
async fn drain(body: Body, budget: u64, time: Duration) {
    let mut stream = body.into_data_stream();
    let mut seen = 0u64;
    let read = async {
        while let Some(Ok(chunk)) = stream.next().await {
            seen += chunk.len() as u64;
            if seen > budget {
                break;
            }
        }
    };
    let ended = tokio::time::timeout(time, read).await.is_ok();
    tracing::debug!(bytes = seen, ended, "drained a refused request body");
}

/// Middleware: wraps the request body (see the module documentation) and marks an answer given
/// before the body was read to its end with `Connection: close`.
pub async fn linger(bounds: Linger, req: Request, next: Next) -> Response {
    let (parts, body) = req.into_parts();
    let seen = Arc::new(Seen::default());
    if body.is_end_stream() {
        seen.ended.store(true, Ordering::Relaxed);
    }
    let expects_continue = parts
        .headers
        .get(header::EXPECT)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.trim().eq_ignore_ascii_case("100-continue"));
    let declared = parts
        .headers
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.trim().parse::<u64>().ok());
    let body = Body::new(Lingering {
        inner: Some(body),
        seen: seen.clone(),
        expects_continue,
        read: 0,
        declared,
        bounds,
    });
    let mut resp = next.run(Request::from_parts(parts, body)).await;
    if !seen.ended.load(Ordering::Relaxed) {
        resp.headers_mut()
            .insert(header::CONNECTION, HeaderValue::from_static("close"));
    }
    resp
}
