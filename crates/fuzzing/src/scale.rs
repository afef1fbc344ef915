//! Reader scaling: every reader on generated inputs of growing size, to show linear time.
//!
//! Each [`ScaleFormat`] writes a valid file of about a requested size (our own writers, or
//! text built here where we have no writer) and reads it back through the public reader
//! users call. [`measure`] times the read at several sizes; the growth ratio of a step is
//! `(t₂ / t₁) / (b₂ / b₁)` — 1 for a linear reader, about the size factor for a quadratic
//! one. Issue 16's target: every step ≤ 1.3. `urbansem bench parsers` prints the table.

use geodata::cloud::{write_cloud_with, Encoding, PointCloud, Precision, WriteOptions};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// A reader under test: how to make an input of a given size and how to read it.
pub struct ScaleFormat {
    /// Short name (`opb`, `pcd-binary`, …).
    pub name: &'static str,
    /// File name extension the reader expects.
    pub ext: &'static str,
    /// Writes a valid input of about `bytes` bytes to the path.
    pub generate: fn(bytes: u64, path: &Path) -> Result<(), String>,
    /// Reads the file; returns the number of items read (points, terms, atoms, elements).
    pub read: fn(path: &Path) -> Result<u64, String>,
}

/// One timed read.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Measurement {
    /// The format's name.
    pub format: &'static str,
    /// File size in bytes.
    pub bytes: u64,
    /// Items the reader returned.
    pub items: u64,
    /// Fastest of the repeated reads, seconds.
    pub seconds: f64,
    /// Megabytes (10⁶ bytes) per second.
    pub mb_per_s: f64,
    /// Growth ratio against the previous size of this format (`None` for the first).
    pub growth: Option<f64>,
}

/// Every format the benchmark knows, in pipeline order.
pub fn formats() -> Vec<ScaleFormat> {
    vec![
        ScaleFormat {
            name: "opb",
            ext: "opb",
            generate: gen_opb,
            read: read_opb,
        },
        ScaleFormat {
            name: "mln-program",
            ext: "mln",
            generate: gen_mln_program,
            read: read_mln_program,
        },
        ScaleFormat {
            name: "mln-evidence",
            ext: "db",
            generate: gen_mln_evidence,
            read: read_mln_evidence,
        },
        ScaleFormat {
            name: "osm-xml",
            ext: "osm",
            generate: gen_osm_xml,
            read: read_osm,
        },
        ScaleFormat {
            name: "ply-ascii",
            ext: "ply",
            generate: |b, p| gen_cloud(b, p, Encoding::Ascii, 60),
            read: read_cloud,
        },
        ScaleFormat {
            name: "ply-binary",
            ext: "ply",
            generate: |b, p| gen_cloud(b, p, Encoding::BinaryLittleEndian, 17),
            read: read_cloud,
        },
        ScaleFormat {
            name: "pcd-ascii",
            ext: "pcd",
            generate: |b, p| gen_cloud(b, p, Encoding::Ascii, 60),
            read: read_cloud,
        },
        ScaleFormat {
            name: "pcd-binary",
            ext: "pcd",
            generate: |b, p| gen_cloud(b, p, Encoding::BinaryLittleEndian, 17),
            read: read_cloud,
        },
        ScaleFormat {
            name: "pcd-compressed",
            ext: "pcd",
            generate: |b, p| gen_cloud(b, p, Encoding::BinaryCompressed, 14),
            read: read_cloud,
        },
        ScaleFormat {
            name: "las",
            ext: "las",
            generate: |b, p| gen_cloud(b, p, Encoding::BinaryLittleEndian, 34),
            read: read_cloud,
        },
        ScaleFormat {
            name: "laz",
            ext: "laz",
            generate: |b, p| gen_cloud(b, p, Encoding::BinaryLittleEndian, 9),
            read: read_cloud,
        },
        ScaleFormat {
            name: "kitti-bin",
            ext: "bin",
            generate: |b, p| gen_cloud(b, p, Encoding::BinaryLittleEndian, 16),
            read: read_cloud,
        },
        ScaleFormat {
            name: "srt",
            ext: "srt",
            generate: gen_srt,
            read: read_srt,
        },
    ]
}

/// Times `format`'s reader on one generated input per size (bytes), fastest of `repeat`
/// rounds.
///
/// The reads are interleaved: every round reads every size, smallest first, so a change of
/// the machine's speed during the run (a shared 2-core VM drifts by tens of per cent over
/// minutes) affects all sizes alike instead of one size's growth ratio. Within a round a
/// smaller input is read more often ([`reads_per_round`]) and its time is the mean of those
/// reads, one sample per size and round: a 60 ms read is far noisier than a 6 s one (its
/// minimum over three reads alone moved a growth ratio by ±0.3), and the minimum of many
/// short reads is a more extreme draw than that of few long ones.
pub fn measure(
    format: &ScaleFormat,
    sizes: &[u64],
    dir: &Path,
    repeat: usize,
    mut progress: impl FnMut(&str),
) -> Result<Vec<Measurement>, String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let mut files: Vec<(PathBuf, u64)> = Vec::new();
    for &size in sizes {
        let path: PathBuf = dir.join(format!("{}-{size}.{}", format.name, format.ext));
        progress(&format!(
            "{}: writing {:.0} MB",
            format.name,
            size as f64 / 1e6
        ));
        (format.generate)(size, &path)?;
        let bytes = std::fs::metadata(&path)
            .map_err(|e| format!("{}: {e}", path.display()))?
            .len();
        files.push((path, bytes));
    }
    let largest = files.iter().map(|f| f.1).max().unwrap_or(1);
    let mut best = vec![f64::INFINITY; files.len()];
    let mut items = vec![0; files.len()];
    let result = (|| {
        for round in 0..repeat.max(1) {
            progress(&format!(
                "{}: reading every size, round {} of {}",
                format.name,
                round + 1,
                repeat.max(1)
            ));
            for (k, (path, bytes)) in files.iter().enumerate() {
                let reads = reads_per_round(*bytes, largest);
                let t = Instant::now();
                for _ in 0..reads {
                    items[k] = (format.read)(path)?;
                }
                best[k] = best[k].min(t.elapsed().as_secs_f64() / reads as f64);
            }
        }
        Ok::<(), String>(())
    })();
    for (path, _) in &files {
        let _ = std::fs::remove_file(path);
    }
    result?;
    let mut out: Vec<Measurement> = Vec::new();
    for (k, &(_, bytes)) in files.iter().enumerate() {
        let growth = out
            .last()
            .map(|prev| (best[k] / prev.seconds) / (bytes as f64 / prev.bytes as f64));
        out.push(Measurement {
            format: format.name,
            bytes,
            items: items[k],
            seconds: best[k],
            mb_per_s: bytes as f64 / 1e6 / best[k].max(1e-12),
            growth,
        });
    }
    Ok(out)
}

/// Reads of an input of `bytes` per round: largest / bytes (1 to 4 096), so that every size
/// reads about as many bytes, and takes about as long, per round — a size 8× and 64× below
/// the largest is read 8× and 64× per round. Equal durations give every size's timing the
/// same exposure to the machine's swings: with √(largest / bytes) reads (session 11), the
/// shorter batches of the small inputs more often fell wholly into a fast spell, and their
/// minimum over the rounds came out up to 1.4× faster per byte than the largest input's.
pub fn reads_per_round(bytes: u64, largest: u64) -> usize {
    ((largest as f64 / bytes.max(1) as f64).round() as usize).clamp(1, 4096)
}

fn write_text(path: &Path, text: &str) -> Result<(), String> {
    geodata::fsio::write_atomic(path, text).map_err(|e| format!("{}: {e}", path.display()))
}

/// A 4-connected denoising grid written as one objective line (≈ 95 bytes per pixel).
fn gen_opb(bytes: u64, path: &Path) -> Result<(), String> {
    let side = ((bytes as f64 / 95.0).sqrt().round() as usize).max(2);
    let problem = pbo::instances::denoising_grid(side, side, 1).to_opb();
    write_text(path, &pbo::opb::write_opb(&problem))
}

fn read_opb(path: &Path) -> Result<u64, String> {
    let p = pbo::opb::read_opb(path).map_err(|e| e.to_string())?;
    Ok(p.poly.num_terms() as u64)
}

/// Many predicates and one formula chaining each to the next (≈ 60 bytes per predicate).
fn gen_mln_program(bytes: u64, path: &Path) -> Result<(), String> {
    let n = (bytes / 60).max(2);
    let mut text = String::with_capacity(bytes as usize + 64);
    for k in 0..n {
        let _ = writeln!(text, "Pred{k}(person, place)");
    }
    for k in 0..n.saturating_sub(1) {
        let _ = writeln!(text, "1.5 Pred{k}(x, y) => Pred{}(x, y)", k + 1);
    }
    write_text(path, &text)
}

fn read_mln_program(path: &Path) -> Result<u64, String> {
    let p = mln::parse::read_program(path).map_err(|e| e.to_string())?;
    Ok(p.formulas.len() as u64)
}

const EVIDENCE_PROGRAM: &str = "Friends(person, person)\nSmokes(person)\n\
                                1.1 Smokes(x) ^ Friends(x, y) => Smokes(y)\n";

/// Ground atoms of two predicates over a growing domain (≈ 26 bytes per atom).
fn gen_mln_evidence(bytes: u64, path: &Path) -> Result<(), String> {
    let n = (bytes / 26).max(1);
    let people = ((n as f64).sqrt() as u64).max(2);
    let mut text = String::with_capacity(bytes as usize + 64);
    for k in 0..n {
        if k % 8 == 0 {
            let _ = writeln!(text, "Smokes(P{})", k % people);
        } else {
            let _ = writeln!(text, "Friends(P{}, P{})", k % people, (k / people) % people);
        }
    }
    write_text(path, &text)
}

fn read_mln_evidence(path: &Path) -> Result<u64, String> {
    let program = mln::parse::parse_program(EVIDENCE_PROGRAM, "evidence-bench.mln")
        .map_err(|e| e.to_string())?;
    let ev = mln::parse::read_evidence(path, &program).map_err(|e| e.to_string())?;
    Ok(ev.len() as u64)
}

/// Square buildings on a grid near Karlsruhe, as OSM XML (≈ 700 bytes per building).
fn gen_osm_xml(bytes: u64, path: &Path) -> Result<(), String> {
    let n = (bytes / 700).max(1);
    let side = (n as f64).sqrt().ceil() as u64;
    let mut text = String::with_capacity(bytes as usize + 1024);
    text.push_str("<?xml version='1.0' encoding='UTF-8'?>\n<osm version=\"0.6\" generator=\"urbansem bench\">\n");
    let step = 2e-4; // ≈ 15–22 m
    for b in 0..n {
        let (i, j) = ((b % side) as f64, (b / side) as f64);
        let (lat, lon) = (49.0 + j * step, 8.3 + i * step);
        for (c, (dlat, dlon)) in [(0.0, 0.0), (0.0, 1e-4), (1e-4, 1e-4), (1e-4, 0.0)]
            .iter()
            .enumerate()
        {
            let _ = writeln!(
                text,
                "  <node id=\"{}\" version=\"1\" lat=\"{:.7}\" lon=\"{:.7}\"/>",
                4 * b + c as u64 + 1,
                lat + dlat,
                lon + dlon
            );
        }
    }
    for b in 0..n {
        let _ = writeln!(text, "  <way id=\"{}\" version=\"1\">", b + 1);
        for c in [0, 1, 2, 3, 0] {
            let _ = writeln!(text, "    <nd ref=\"{}\"/>", 4 * b + c + 1);
        }
        text.push_str("    <tag k=\"building\" v=\"yes\"/>\n  </way>\n");
    }
    text.push_str("</osm>\n");
    write_text(path, &text)
}

fn read_osm(path: &Path) -> Result<u64, String> {
    let map = geodata::osm::OsmMap::load(path).map_err(|e| e.to_string())?;
    Ok(map.building_count() as u64)
}

/// A seeded street-like cloud with intensity and labels; `bytes_per_point` sizes it.
fn synthetic_cloud(points: usize) -> PointCloud {
    let mut cloud = PointCloud {
        positions: Vec::with_capacity(points),
        precision: Precision::F32,
        intensity: Some(Vec::with_capacity(points)),
        label: Some(Vec::with_capacity(points)),
        ..PointCloud::default()
    };
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    for i in 0..points {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        let r = |s: u64, k: u32| ((s >> k) & 0xFFFF) as f64 / 65535.0;
        let t = i as f64 * 0.01;
        cloud
            .positions
            .push([t % 200.0, 10.0 * r(state, 0), 3.0 * r(state, 16)]);
        if let Some(v) = cloud.intensity.as_mut() {
            v.push(r(state, 32) as f32);
        }
        if let Some(v) = cloud.label.as_mut() {
            v.push((state >> 48) as u8 % 8);
        }
    }
    cloud
}

fn gen_cloud(
    bytes: u64,
    path: &Path,
    encoding: Encoding,
    bytes_per_point: u64,
) -> Result<(), String> {
    let cloud = synthetic_cloud((bytes / bytes_per_point).max(1) as usize);
    write_cloud_with(path, &cloud, &WriteOptions { encoding }).map_err(|e| e.to_string())
}

fn read_cloud(path: &Path) -> Result<u64, String> {
    let cloud = geodata::cloud::read_cloud(path).map_err(|e| e.to_string())?;
    Ok(cloud.len() as u64)
}

/// A semantic map built from a synthetic cloud (≈ 30 bytes per occupied cell).
fn gen_srt(bytes: u64, path: &Path) -> Result<(), String> {
    let cloud = synthetic_cloud((bytes / 30).max(1) as usize);
    let mut map =
        srtree::map::SrMap::new(srtree::map::MapOptions::default()).map_err(|e| e.to_string())?;
    map.insert_cloud(&cloud, None).map_err(|e| e.to_string())?;
    srtree::io::write_map(path, &srtree::semantic::SemanticMap::new(map)).map_err(|e| e.to_string())
}

fn read_srt(path: &Path) -> Result<u64, String> {
    let map = srtree::io::read_map(path).map_err(|e| e.to_string())?;
    Ok(map.cells.len() as u64)
}

#[cfg(test)]
mod tests {
    use super::reads_per_round;

    #[test]
    fn smaller_inputs_are_read_more_often() {
        assert_eq!(reads_per_round(128, 128), 1);
        assert_eq!(reads_per_round(16, 128), 8);
        assert_eq!(reads_per_round(2, 128), 64);
        assert_eq!(reads_per_round(1, u64::MAX), 4096);
        assert_eq!(reads_per_round(0, 0), 1);
        assert_eq!(reads_per_round(200, 100), 1);
    }
}
