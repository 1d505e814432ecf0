//! `softtouch db init`, `softtouch db copy`, `softtouch db new-identity`.

use super::{Failure, io_failure};
use clap::Subcommand;
use softtouch_store::{DbTarget, Store};
use std::io::Write;

/// Parses a `--db`, `--from` or `--to` into a [`softtouch_store::DbTarget`]. Not clap's
/// `FromStr` parser: its error repeats the raw value ("invalid value 'postgres://u:PW@…'"),
/// password and all; this one says only the store's own, redacted, reason.
#[derive(Debug, Clone, Copy)]
pub struct DbTargetParser;

impl clap::builder::TypedValueParser for DbTargetParser {
    type Value = softtouch_store::DbTarget;

    fn parse_ref(
        &self,
        cmd: &clap::Command,
        arg: Option<&clap::Arg>,
        value: &std::ffi::OsStr,
    ) -> Result<Self::Value, clap::Error> {
        let name = arg
            .and_then(clap::Arg::get_long)
            .map_or_else(|| "the database".to_owned(), |long| format!("--{long}"));
        let fail = |why: String| {
            clap::Error::raw(
                clap::error::ErrorKind::ValueValidation,
                format!("{name}: {why}\n"),
            )
            .with_cmd(cmd)
        };
        let text = value
            .to_str()
            .ok_or_else(|| fail("not valid UTF-8".to_owned()))?;
        text.parse().map_err(fail)
    }
}

#[derive(Debug, Subcommand)]
pub enum DbCommand {
    /// Create the database (or bring an existing one to this version's schema). A
    /// PostgreSQL database must exist on its server (`createdb softtouch`); this sets up
    /// its tables.
    #[command(
        after_help = "Examples:\n  softtouch db init\n  softtouch --db /data/lab.db db init\n  softtouch --db postgres://rig@db.lab/softtouch db init"
    )]
    Init,
    /// Copy runs, datasets, models, grasp sessions, calibrations and results from one
    /// store into another (SQLite or PostgreSQL, either way). Every object is checked
    /// row for row by sha256 after it is written; running it again copies only what is
    /// new (a run still being collected gets its new samples). Ids are the destination's
    /// own; a dataset or model whose name the destination already uses is skipped and
    /// said.
    #[command(
        after_help = "Examples:\n  softtouch db copy --from rig2.db --to postgres://lab@db.lab/softtouch\n  softtouch db copy --from postgres://lab@db.lab/softtouch --to backup.db"
    )]
    Copy {
        /// The store to read (a path or postgres:// URL); never written to except its
        /// identity, made once.
        #[arg(long, value_parser = DbTargetParser)]
        from: DbTarget,
        /// The store to write (created and migrated if it is a new file).
        #[arg(long, value_parser = DbTargetParser)]
        to: DbTarget,
    },
    /// Give this store an identity of its own for `db copy`. A copied database file or
    /// a restored backup keeps its original's identity; once it has been written on its
    /// own, `db copy` refuses it ("not as it was copied from this store before"). After
    /// this, everything it holds is copied as new objects (even those its original
    /// copied before: the destination then holds them twice).
    #[command(after_help = "Example:\n  softtouch --db rig2-restored.db db new-identity")]
    NewIdentity,
}

pub async fn run(cmd: DbCommand, db: &DbTarget, out: &mut dyn Write) -> Result<(), Failure> {
    match cmd {
        DbCommand::Init => {
            let store = Store::open(db).await?;
            let integrity = store.integrity_check().await?;
            store.close().await;
            writeln!(
                out,
                "database {} ready: schema {}, integrity {integrity}",
                db.display(),
                Store::schema_version()
            )
            .map_err(io_failure)
        }
        DbCommand::Copy { from, to } => copy(&from, &to, out).await,
        DbCommand::NewIdentity => {
            let store = Store::open_existing(db).await?;
            let result = store.new_identity().await;
            store.close().await;
            let (old, new) = result?;
            writeln!(
                out,
                "{}: identity {old} → {new}; `db copy` now copies it as a store of its own",
                db.display()
            )
            .map_err(io_failure)
        }
    }
}

async fn copy(from: &DbTarget, to: &DbTarget, out: &mut dyn Write) -> Result<(), Failure> {
    let started = std::time::Instant::now();
    let source = Store::open_existing(from).await?;
    let dest = match Store::open(to).await {
        Ok(dest) => dest,
        Err(e) => {
            source.close().await;
            return Err(e.into());
        }
    };
    let mut lines = Vec::new();
    let result = source
        .copy_into(&dest, &mut |line: &str| {
            eprintln!("{line}");
            lines.push(line.to_owned());
        })
        .await;
    source.close().await;
    dest.close().await;
    let report = result?;
    let list = |items: &[(String, u64)]| {
        if items.is_empty() {
            "nothing".to_owned()
        } else {
            items
                .iter()
                .map(|(k, n)| format!("{n} {k}"))
                .collect::<Vec<_>>()
                .join(", ")
        }
    };
    writeln!(
        out,
        "copied {} → {} in {:.1} s\n  new: {}\n  already there: {}\n  rows written: {}\n  rows checked by sha256: {}",
        from.display(),
        to.display(),
        started.elapsed().as_secs_f64(),
        list(&report.new),
        list(&report.already),
        list(&report.rows),
        list(&report.checked),
    )
    .map_err(io_failure)?;
    for why in &report.skipped {
        writeln!(out, "  skipped: {why}").map_err(io_failure)?;
    }
    Ok(())
}
