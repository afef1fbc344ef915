//! Every real scan under `../shared/data/lidar/` loads with its labels and pose, and each
//! dataset's georeference puts it where its documentation says.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use geodata::classes::Class;
use geodata::cloud::kitti::KITTI_POINT_BYTES;
use geodata::datasets::kitti360::Kitti360Sequence;
use geodata::datasets::kitti_raw::KittiRawDrive;
use geodata::datasets::mcd::McdSequence;
use geodata::datasets::{open_sequence, LidarSequence, Scan, SequenceKind};
use geodata::projection::LocalFrame;
use nalgebra::{Point3, Vector3};
use std::path::PathBuf;

fn data_dir(rel: &str) -> PathBuf {
    let p = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data")).join(rel);
    assert!(p.exists(), "missing shared data: {}", p.display());
    p
}

/// MCD `kth_day_06` (30 labelled Ouster scans).
fn mcd_kth_day_06() -> McdSequence {
    let dir = data_dir("lidar/mcd_kth_day_06");
    McdSequence::open(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
}

/// KITTI-360 `2013_05_28_drive_0009` (25 labelled Velodyne scans).
fn kitti360_drive_0009() -> Kitti360Sequence {
    let dir = data_dir("lidar/kitti360_2013_05_28_drive_0009");
    Kitti360Sequence::open(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
}

/// KITTI raw `2011_09_26_drive_0005`, frame 0.
fn kitti_raw_drive_0005() -> KittiRawDrive {
    let dir = data_dir("lidar/kitti_raw_2011_09_26_drive_0005_frame0");
    KittiRawDrive::open(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
}

fn file_points(scan: &Scan) -> usize {
    let len = std::fs::metadata(&scan.path).unwrap().len();
    assert_eq!(len % KITTI_POINT_BYTES, 0, "{}", scan.path.display());
    (len / KITTI_POINT_BYTES) as usize
}

/// Mean height of a class's points above (negative: below) the sensor, in the world frame.
fn class_height_below_sensor(scan: &Scan, class: Class) -> Option<f64> {
    let sensor_z = scan.world_from_sensor.translation.vector.z;
    let (mut sum, mut n) = (0.0, 0usize);
    for (i, p) in scan.cloud.positions.iter().enumerate() {
        if scan.cloud.class(i) == class {
            let w = scan
                .world_from_sensor
                .transform_point(&Point3::new(p[0], p[1], p[2]));
            sum += w.z - sensor_z;
            n += 1;
        }
    }
    (n > 100).then(|| sum / n as f64)
}

#[test]
fn mcd_every_scan_loads_with_labels_and_pose() {
    let seq = mcd_kth_day_06();
    assert_eq!(seq.pose_count(), 8897);
    let frames = seq.frames().unwrap();
    assert_eq!(frames.len(), 30);
    assert_eq!(frames.first(), Some(&11));
    assert_eq!(frames.last(), Some(&98));
    let mut buildings = 0usize;
    for f in frames {
        let scan = seq.load_scan(f).unwrap();
        assert_eq!(scan.cloud.len(), 65_536);
        assert_eq!(scan.cloud.len(), file_points(&scan));
        let raw = scan.cloud.raw_label.as_ref().unwrap();
        assert_eq!(raw.len(), scan.cloud.len());
        assert_eq!(scan.cloud.label.as_ref().unwrap().len(), scan.cloud.len());
        assert!(
            raw.iter().all(|&r| r <= 28),
            "frame {f}: MCD ids are 0..=28"
        );
        buildings += scan.cloud.class_histogram()[Class::Building.id() as usize];
        // The lidar's z axis points up, and the road/sidewalk lie 1–3 m below the sensor.
        let up = scan.world_from_sensor.rotation * Vector3::z();
        assert!(up.z > 0.95, "frame {f}: lidar z axis {up}");
        let below = class_height_below_sensor(&scan, Class::Sidewalk).unwrap();
        assert!(
            (-3.0..-0.5).contains(&below),
            "frame {f}: sidewalk {below:.2} m below the sensor"
        );
    }
    assert!(buildings > 30 * 10_000, "{buildings} building points");
}

#[test]
fn mcd_first_pose_is_at_the_documented_position() {
    let seq = mcd_kth_day_06();
    let body = seq.world_from_body(11).unwrap();
    let t = body.translation.vector;
    assert!((t.x - 64.39).abs() < 0.01 && (t.y - 66.48).abs() < 0.01 && (t.z - 38.51).abs() < 0.01);
    let (lat, lon) = seq.georef().to_wgs84([t.x, t.y]);
    assert!((lat - 59.348_268_650).abs() < 1e-7, "lat {lat}");
    assert!((lon - 18.073_204_280).abs() < 1e-7, "lon {lon}");
    // The lidar is a few centimetres from the body origin.
    let lidar = seq.world_from_lidar(11).unwrap().translation.vector;
    assert!((lidar - t).norm() < 0.2, "{}", (lidar - t).norm());
}

#[test]
fn kitti360_every_scan_loads_with_labels_and_pose() {
    let seq = kitti360_drive_0009();
    assert_eq!(seq.pose_count(), 1201);
    let frames = seq.frames().unwrap();
    assert_eq!(frames.len(), 25);
    let frame = LocalFrame::new(48.981, 8.393).unwrap();
    let mut path_m = 0.0;
    let mut last: Option<[f64; 3]> = None;
    for f in frames {
        let scan = seq.load_scan(f).unwrap();
        let n = scan.cloud.len();
        assert_eq!(n, file_points(&scan));
        assert!((80_000..130_000).contains(&n), "frame {f}: {n} points");
        assert_eq!(scan.cloud.raw_label.as_ref().unwrap().len(), n);
        assert_eq!(scan.cloud.label.as_ref().unwrap().len(), n);
        let (lat, lon) = scan.sensor_wgs84();
        assert!(
            (48.9795..48.9828).contains(&lat) && (8.3903..8.3966).contains(&lon),
            "frame {f}: {lat}, {lon}"
        );
        let h = scan.cloud.class_histogram();
        assert!(
            h[Class::Street.id() as usize] > 1000,
            "frame {f}: street points {h:?}"
        );
        let below = class_height_below_sensor(&scan, Class::Street).unwrap();
        assert!(
            (-2.5..-1.2).contains(&below),
            "frame {f}: road {below:.2} m below the sensor"
        );
        let pose = scan.pose_in_local(&frame);
        if let Some(l) = last {
            path_m +=
                ((pose.position_m[0] - l[0]).powi(2) + (pose.position_m[1] - l[1]).powi(2)).sqrt();
        }
        last = Some(pose.position_m);
    }
    // SOURCES-geo.md: frames 2000–2960 follow an 820 m path.
    assert!((700.0..950.0).contains(&path_m), "path {path_m:.0} m");
}

#[test]
fn kitti_raw_scan_loads_at_its_oxts_position() {
    let drive = kitti_raw_drive_0005();
    assert_eq!(drive.frames().unwrap(), vec![0]);
    let oxts = drive.oxts(0).unwrap();
    assert!((oxts.lat_deg - 49.011_212_804).abs() < 1e-9);
    assert!((oxts.lon_deg - 8.422_885_042).abs() < 1e-9);
    assert!((oxts.alt_m - 112.83).abs() < 0.01);
    assert!((oxts.yaw_rad - -1.2219).abs() < 1e-4);
    let imu = drive.world_from_imu(0).unwrap();
    let (lat, lon) = drive
        .georef()
        .to_wgs84([imu.translation.vector.x, imu.translation.vector.y]);
    assert!((lat - 49.011_212_804).abs() < 1e-9 && (lon - 8.422_885_042).abs() < 1e-9);
    let scan = drive.load_scan(0).unwrap();
    assert_eq!(scan.cloud.len(), 123_397);
    assert_eq!(scan.cloud.len(), file_points(&scan));
    assert!(scan.cloud.label.is_none());
    // The Velodyne sits 0.8 m ahead of and 0.8 m above the IMU (calib_imu_to_velo.txt).
    let d = scan.world_from_sensor.translation.vector - imu.translation.vector;
    assert!((0.7..1.4).contains(&d.norm()), "{d}");
    assert!((0.6..1.0).contains(&d.z), "{d}");
    // The Velodyne looks where the car heads (yaw −1.22 rad), and the ground is ~1.7 m below.
    let pose = scan.pose_in_local(&LocalFrame::new(49.0112, 8.4229).unwrap());
    assert!(
        (pose.yaw_rad - -1.2219).abs() < 0.02,
        "yaw {}",
        pose.yaw_rad
    );
    let mut z: Vec<f64> = scan.cloud.positions.iter().map(|p| p[2]).collect();
    z.sort_by(f64::total_cmp);
    let ground = z[z.len() / 10];
    assert!((-2.2..-1.3).contains(&ground), "10th percentile z {ground}");
}

#[test]
fn a_missing_file_names_its_path() {
    let e = McdSequence::open("/nonexistent/mcd").unwrap_err();
    assert!(
        e.to_string().contains("/nonexistent/mcd/pose_inW.csv"),
        "{e}"
    );
    let seq = mcd_kth_day_06();
    let e = seq.load_scan(12).unwrap_err();
    assert!(e.to_string().contains("0000000012.bin"), "{e}");
}

/// What a sequence yields, frame by frame: (frame, points, first point, world_from_sensor,
/// raw label histogram).
type Yield = Vec<(
    u64,
    usize,
    Option<[f64; 3]>,
    nalgebra::Isometry3<f64>,
    Vec<(u32, usize)>,
)>;

fn yields(seq: &dyn LidarSequence) -> Yield {
    seq.frames()
        .unwrap()
        .into_iter()
        .map(|f| {
            let scan = seq.load_scan(f).unwrap();
            assert_eq!(scan.frame, f);
            assert_eq!(scan.world_from_sensor, seq.world_from_sensor(f).unwrap());
            let mut hist = std::collections::BTreeMap::new();
            for &r in scan.cloud.raw_label.iter().flatten() {
                *hist.entry(r).or_insert(0usize) += 1;
            }
            let labels = scan.cloud.label.as_ref().map(Vec::len);
            assert!(labels.is_none() || labels == Some(scan.cloud.len()));
            (
                f,
                scan.cloud.len(),
                scan.cloud.positions.first().copied(),
                scan.world_from_sensor,
                hist.into_iter().collect(),
            )
        })
        .collect()
}

/// The trait object yields what the concrete reader does, scan by scan.
fn same_as_concrete(rel: &str, kind: SequenceKind, concrete: &dyn LidarSequence) -> Yield {
    let dir = data_dir(rel);
    assert_eq!(SequenceKind::of(&dir), Some(kind));
    let seq = open_sequence(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    assert_eq!(seq.kind(), Some(kind));
    assert_eq!(seq.name(), kind.name());
    assert_eq!(seq.dir(), dir.as_path());
    assert_eq!(seq.georeference(), concrete.georeference());
    assert_eq!(seq.pose_frames().unwrap(), concrete.pose_frames().unwrap());
    let got = yields(seq.as_ref());
    assert_eq!(got, yields(concrete));
    got
}

#[test]
fn open_sequence_yields_the_concrete_readers_scans() {
    let mcd = mcd_kth_day_06();
    let got = same_as_concrete("lidar/mcd_kth_day_06", SequenceKind::Mcd, &mcd);
    assert_eq!(got.len(), 30);
    let (frame, points, _, pose, hist) = &got[0];
    assert_eq!((*frame, *points), (11, 65_536));
    assert_eq!(*pose, mcd.world_from_lidar(11).unwrap());
    assert_eq!(
        hist.iter().map(|(_, n)| n).sum::<usize>(),
        65_536,
        "every MCD point is labelled"
    );
    let mcd_poses = mcd.pose_frames().collect::<Vec<_>>();
    assert_eq!(mcd_poses.len(), 8897);

    let kitti = kitti360_drive_0009();
    let got = same_as_concrete(
        "lidar/kitti360_2013_05_28_drive_0009",
        SequenceKind::Kitti360,
        &kitti,
    );
    assert_eq!(got.len(), 25);
    let (frame, points, _, pose, hist) = &got[0];
    assert_eq!(*pose, kitti.world_from_velodyne(*frame).unwrap());
    assert_eq!(hist.iter().map(|(_, n)| n).sum::<usize>(), *points);
    assert!(
        hist.iter().any(|&(raw, n)| raw == 7 && n > 1000),
        "road points"
    );

    let raw = kitti_raw_drive_0005();
    let got = same_as_concrete(
        "lidar/kitti_raw_2011_09_26_drive_0005_frame0",
        SequenceKind::KittiRaw,
        &raw,
    );
    assert_eq!(got.len(), 1);
    let (frame, points, _, pose, hist) = &got[0];
    assert_eq!((*frame, *points), (0, 123_397));
    assert_eq!(*pose, raw.load_scan(0).unwrap().world_from_sensor);
    assert!(hist.is_empty(), "KITTI raw has no labels");
    assert!(!LidarSequence::labelled(&raw));
}

#[test]
fn an_unknown_layout_names_its_folder() {
    let dir = data_dir("lidar");
    assert_eq!(SequenceKind::of(&dir), None);
    let e = open_sequence(&dir).err().unwrap();
    assert!(e.to_string().contains(&*dir.to_string_lossy()), "{e}");
    assert!(e.to_string().contains("not a LiDAR sequence"), "{e}");
}
