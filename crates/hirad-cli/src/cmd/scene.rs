//! `hirad scene SCENE --out FILE`: write a scene (built-in or loaded) as `.obj` (+ `.mtl`),
//! `.glb`, or `.toml` (scene description + `.obj` + `.mtl`, keeping sun, sky and cameras).

use super::info::LoadArgs;
use crate::Global;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene: a built-in name or a file path.
    pub scene: String,
    /// Output file: `.obj` (writes a `.mtl` next to it), `.glb`, or `.toml` (writes `.obj` and
    /// `.mtl` next to it; keeps sun, sky and cameras) (required).
    #[arg(long, short)]
    pub out: std::path::PathBuf,
    #[command(flatten)]
    pub load: LoadArgs,
}

pub fn run(args: Args, g: &Global) -> anyhow::Result<()> {
    let scene = super::load_scene(&args.scene, &args.load.options())?;
    hirad::scene::export::write_scene(&args.out, &scene)?;
    if g.json {
        return super::print_json(&serde_json::json!({
            "scene": scene.name,
            "out": args.out,
            "triangles": scene.num_triangles(),
            "materials": scene.materials.len(),
            "objects": scene.objects.len(),
        }));
    }
    if !g.quiet {
        println!(
            "wrote {} ({} triangles, {} materials, {} objects)",
            args.out.display(),
            scene.num_triangles(),
            scene.materials.len(),
            scene.objects.len()
        );
    }
    Ok(())
}
