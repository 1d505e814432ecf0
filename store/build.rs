// `sqlx::migrate!` embeds ../migrations/{sqlite,postgres} at build time: a new or edited migration
// must rebuild this crate (cargo does not track that folder by itself).
fn main() {
    println!("cargo:rerun-if-changed=../migrations/sqlite");
    println!("cargo:rerun-if-changed=../migrations/postgres");
}
