//! The byte link under the Modbus client, able to throw away a late reply.
//!
//! A reply that comes after its request timed out stays in the port and would be
//! read as the reply to the next request: every later reply would then be one
//! behind (tokio-modbus clears only its own buffer before a request, not the
//! port's). [`Flushable`] drops whatever is waiting in the port when asked, right
//! before the next request goes out.

use std::io;
use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::task::{Context, Poll};
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};

/// The handle the driver keeps: ask for a flush, count what it dropped.
#[derive(Debug, Clone, Default)]
pub struct FlushHandle {
    requested: Arc<AtomicBool>,
    dropped_bytes: Arc<AtomicU64>,
}

impl FlushHandle {
    /// Drop what is waiting in the port before the next write.
    pub fn request(&self) {
        self.requested.store(true, Ordering::SeqCst);
    }

    /// Bytes dropped so far.
    #[must_use]
    pub fn dropped_bytes(&self) -> u64 {
        self.dropped_bytes.load(Ordering::Relaxed)
    }
}

/// A transport that drops the bytes waiting in it before a write, once asked.
#[derive(Debug)]
pub struct Flushable<T> {
    inner: T,
    handle: FlushHandle,
}

impl<T> Flushable<T> {
    /// Wrap `inner`; `handle` asks for flushes.
    pub const fn new(inner: T, handle: FlushHandle) -> Self {
        Self { inner, handle }
    }
}

impl<T: AsyncRead + Unpin> Flushable<T> {
    /// Reads and drops what the port holds now, without waiting for more. A `Pending`
    /// read leaves a waker behind, which at worst wakes the writer once more.
    fn drain(&mut self, cx: &mut Context<'_>) {
        let mut chunk = [0u8; 256];
        loop {
            let mut buf = ReadBuf::new(&mut chunk);
            match Pin::new(&mut self.inner).poll_read(cx, &mut buf) {
                Poll::Ready(Ok(())) if !buf.filled().is_empty() => {
                    self.handle
                        .dropped_bytes
                        .fetch_add(buf.filled().len() as u64, Ordering::Relaxed);
                }
                // End of stream, an error (the next read reports it), or nothing more.
                _ => return,
            }
        }
    }
}

impl<T: AsyncRead + Unpin> AsyncRead for Flushable<T> {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_read(cx, buf)
    }
}

impl<T: AsyncRead + AsyncWrite + Unpin> AsyncWrite for Flushable<T> {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        data: &[u8],
    ) -> Poll<io::Result<usize>> {
        if self.handle.requested.swap(false, Ordering::SeqCst) {
            self.drain(cx);
        }
        Pin::new(&mut self.inner).poll_write(cx, data)
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::{AsyncReadExt, AsyncWriteExt};

    #[tokio::test]
    async fn a_requested_flush_drops_only_what_waits_before_the_next_write() {
        let (a, mut b) = tokio::io::duplex(64);
        let handle = FlushHandle::default();
        let mut link = Flushable::new(a, handle.clone());
        b.write_all(b"late reply").await.expect("write");
        // Not asked: the bytes are read as they are.
        let mut got = [0u8; 4];
        link.read_exact(&mut got).await.expect("read");
        assert_eq!(&got, b"late");
        handle.request();
        link.write_all(b"next request").await.expect("write");
        assert_eq!(handle.dropped_bytes(), 6);
        let mut req = [0u8; 12];
        b.read_exact(&mut req).await.expect("read");
        assert_eq!(&req, b"next request");
        // What comes after the write is the new reply, untouched.
        b.write_all(b"fresh").await.expect("write");
        let mut fresh = [0u8; 5];
        link.read_exact(&mut fresh).await.expect("read");
        assert_eq!(&fresh, b"fresh");
        // An empty port: a flush drops nothing and the write goes through.
        handle.request();
        link.write_all(b"x").await.expect("write");
        assert_eq!(handle.dropped_bytes(), 6);
    }
}
