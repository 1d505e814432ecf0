//! `softtouch db init`.

use super::{Failure, io_failure};
use clap::Subcommand;
use softtouch_store::Store;
use std::io::Write;
use std::path::Path;

#[derive(Debug, Subcommand)]
pub enum DbCommand {
    /// Create the database (or bring an existing one to this version's schema).
    #[command(after_help = "Examples:\n  softtouch db init\n  softtouch --db /data/lab.db db init")]
    Init,
}

pub async fn run(cmd: DbCommand, db: &Path, out: &mut dyn Write) -> Result<(), Failure> {
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
    }
}
