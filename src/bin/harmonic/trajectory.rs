//! `--trajectory`: the state of every particle at recorded frames, as CSV.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use harmonic::Simulation;

/// Whether `a` and `b` are one file (device and inode on Unix; the canonical paths
/// elsewhere). A path that does not exist is no file yet.
pub fn same_file(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        match (std::fs::metadata(a), std::fs::metadata(b)) {
            (Ok(a), Ok(b)) => (a.dev(), a.ino()) == (b.dev(), b.ino()),
            _ => false,
        }
    }
    #[cfg(not(unix))]
    {
        matches!((a.canonicalize(), b.canonicalize()), (Ok(a), Ok(b)) if a == b)
    }
}

/// The file with its header and the state at step 0.
pub fn create(path: &Path, sim: &Simulation) -> Result<BufWriter<File>, String> {
    let f = File::create(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut w = BufWriter::new(f);
    writeln!(w, "step,time,particle,x,y,z,vx,vy,vz").map_err(|e| e.to_string())?;
    write_rows(&mut w, sim, 0).map_err(|e| e.to_string())?;
    Ok(w)
}

/// One row per particle: `step,time,particle,x,y,z,vx,vy,vz` (scene order).
pub fn write_rows(w: &mut impl Write, sim: &Simulation, step: u64) -> std::io::Result<()> {
    let t = step as f64 * sim.config().dt;
    for (i, (x, v)) in sim.positions().iter().zip(sim.velocities()).enumerate() {
        writeln!(
            w,
            "{step},{t},{i},{},{},{},{},{},{}",
            x.x, x.y, x.z, v.x, v.y, v.z
        )?;
    }
    Ok(())
}
