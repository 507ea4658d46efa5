//! The report's CSV files: `errors.csv` (one row per scene and
//! configuration) and `scaling.csv` (one row per size and configuration,
//! with build time and memory per light).

use std::error::Error;
use std::fmt::Write as _;
use std::fs;
use std::path::Path;

use crate::measure::Record;
use crate::scaling::ScalingRow;

/// Header of `errors.csv` and `scaling.csv`.
pub const CSV_HEADER: &str = "scene,lights,method,parameter,time_per_point_us,\
mean_rel_error,max_rel_error,mean_rel_bound,max_rel_bound,mean_cost,\
mean_shadow_rays,mean_classify_queries";

impl Record {
    /// The record as a CSV line (without newline).
    pub fn csv(&self) -> String {
        let m = &self.measurement;
        let (mean_bound, max_bound) = match m.bound {
            Some((mean, max)) => (format!("{mean:.6e}"), format!("{max:.6e}")),
            None => (String::new(), String::new()),
        };
        let (rays, classify) = match m.queries {
            Some((rays, classify)) => (format!("{rays:.1}"), format!("{classify:.1}")),
            None => (String::new(), String::new()),
        };
        format!(
            "{},{},{},{},{:.4},{:.6e},{:.6e},{},{},{:.1},{},{}",
            self.scene,
            self.lights,
            self.method.id(),
            self.parameter,
            m.seconds_per_point * 1e6,
            m.mean_error,
            m.max_error,
            mean_bound,
            max_bound,
            m.mean_cost,
            rays,
            classify
        )
    }
}

/// Writes `errors.csv`.
pub fn write_csv(path: &Path, records: &[Record]) -> Result<(), Box<dyn Error>> {
    let mut text = String::from(CSV_HEADER);
    text.push('\n');
    for r in records {
        text.push_str(&r.csv());
        text.push('\n');
    }
    fs::write(path, text)?;
    println!("  wrote {}", path.display());
    Ok(())
}

/// Writes `scaling.csv`.
pub fn write_scaling_csv(path: &Path, rows: &[ScalingRow]) -> Result<(), Box<dyn Error>> {
    let mut text = format!("{CSV_HEADER},build_ns_per_light,memory_bytes_per_light\n");
    for row in rows {
        let build = row.build.as_secs_f64() * 1e9 / row.lights as f64;
        let memory = row.memory as f64 / row.lights as f64;
        for r in &row.records {
            let _ = writeln!(text, "{},{build:.1},{memory:.1}", r.csv());
        }
    }
    fs::write(path, text)?;
    println!("  wrote {}", path.display());
    Ok(())
}
