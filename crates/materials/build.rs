//! Embeds every file under `materials/` so an installed binary never hunts for them.

#[path = "../build/embed.rs"]
mod embed;

fn main() {
    embed::embed(&embed::Embed {
        dir: "../../materials",
        endings: &[".json"],
        skip: &[],
        out: "embedded.rs",
        item: "/// Every file under `materials/`: (path relative to it, contents).\npub static EMBEDDED: &[(&str, &str)]",
    });
}
