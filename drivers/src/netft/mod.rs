//! ATI Net F/T over RDT (UDP 49152, big-endian; calibration on TCP 49151).
//!
//! - [`codec`]: pure encode/decode of requests, records and the calibration reply;
//!   never panics on any bytes.
//! - [`client`]: [`NetFtClient`], a [`crate::ForceSensor`]: real-time or buffered
//!   streaming, a lost start command retried, software bias, lost records counted
//!   from `rdt_sequence` (wrap at 2^32 included), records going backwards dropped
//!   and counted, status words decoded (warning vs fault) and latched, counts scaled
//!   with counts-per-unit read from the sensor (TCP request or `netftapi2.xml`) or
//!   given; a stream that falls silent asked for again; every reading stamped on the
//!   injected clock from its sequence ([`stamp`]: datagrams read together were still
//!   sampled a period apart), `ft_sequence` kept as sent.
//! - [`server`]: a simulated Net F/T serving any [`crate::ForceSensor`] over real UDP
//!   RDT and the TCP calibration request ([`server::serve`]).

pub mod client;
pub mod codec;
pub mod server;
mod stamp;

pub use client::{NetFtClient, NetFtConfig, NetFtStats, Scaling, StreamMode};
pub use codec::Calibration;
pub use server::{NetFtServer, ServerConfig, ServerStats, serve};
