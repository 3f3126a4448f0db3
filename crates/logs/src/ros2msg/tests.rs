use super::*;
use lightpose_core::StdDev;

fn est(status: Status) -> PoseEstimate {
    let mut e = PoseEstimate::empty(7, 0.7, status, "test");
    (e.x, e.y, e.z, e.pitch_deg, e.yaw_deg, e.surge) = (
        Some(5.0),
        Some(-0.5),
        Some(0.25),
        Some(10.0),
        Some(-20.0),
        Some(0.3),
    );
    e.std = StdDev {
        x: Some(0.1),
        y: Some(0.2),
        z: Some(0.05),
        pitch: Some(1.0),
        yaw: Some(2.0),
        surge: Some(0.02),
        roll: None,
    };
    e
}

#[test]
fn only_ok_complete_poses_are_solved() {
    assert!(solve(&est(Status::Ok), 1.5).is_some());
    assert!(solve(&est(Status::Initialising), 1.5).is_none());
    let mut e = est(Status::Ok);
    e.std.yaw = None;
    assert!(solve(&e, 1.5).is_none(), "a yaw without its σ");
    e = est(Status::Ok);
    e.std.x = Some(f64::NAN);
    assert!(
        solve(&e, 1.5).is_none(),
        "a NaN σ never reaches a covariance"
    );
    e = est(Status::Ok);
    e.z = Some(f64::INFINITY);
    assert!(solve(&e, 1.5).is_none());
}

#[test]
fn covariance_is_finite_positive_with_roll_unobserved() {
    let s = solve(&est(Status::Ok), 1.5).expect("ok");
    let d = s.pose_cov.diag();
    assert_eq!(d[0], 0.1f64 * 0.1);
    assert!((d[4] - 1f64.to_radians().powi(2)).abs() < 1e-15);
    assert_eq!(d[3], UNOBSERVED_ANGLE_VAR, "roll: no reading says it");
    for v in s.odometry(&Frames::default()).twist.covariance.diag() {
        assert!(v.is_finite() && v > 0.0, "{v}");
    }
    assert!(d.iter().all(|v| v.is_finite() && *v > 0.0), "{d:?}");
    let off: usize = (0..36)
        .filter(|i| i % 7 != 0 && s.pose_cov.0[*i] != 0.0)
        .count();
    assert_eq!(off, 0);
}

#[test]
fn base_link_is_flu_of_the_frd_body() {
    // Level, bow toward the beacon (yaw 0 faces −x_B): FLU's forward is
    // −x_B, its left −y_B, its up +z_B: a half turn about z.
    let q = base_link_in_beam(&Attitude::new(Angle::ZERO, Angle::ZERO));
    assert!(
        (q.z.abs() - 1.0).abs() < 1e-12 && q.w.abs() < 1e-12,
        "{q:?}"
    );
    // Any attitude: the matrix back from the quaternion is R_BV with its
    // y and z columns negated.
    let att = Attitude::new(Angle::from_deg(12.0), Angle::from_deg(-75.0))
        .with_roll(Angle::from_deg(4.0));
    let r = rotation(&base_link_in_beam(&att));
    let rbv = att.r_bv();
    for i in 0..3 {
        assert!((r[i][0] - rbv[i][0]).abs() < 1e-12);
        assert!((r[i][1] + rbv[i][1]).abs() < 1e-12);
        assert!((r[i][2] + rbv[i][2]).abs() < 1e-12);
    }
}

#[test]
fn stamps_and_names() {
    let t = Time::from_unix(1_700_000_000.25);
    assert_eq!((t.sec, t.nanosec), (1_700_000_000, 250_000_000));
    assert_eq!(Time::from_unix(f64::NAN), Time::default());
    assert_eq!(
        POSE_TYPE.dds(),
        "geometry_msgs::msg::dds_::PoseWithCovarianceStamped_"
    );
    assert_eq!(ODOM_TYPE.ros(), "nav_msgs/msg/Odometry");
}

#[test]
fn the_site_puts_the_beacon_axis_on_its_heading() {
    // An axis heading east (90°): x_B is ENU's +x, no rotation.
    let tf = site_tf(
        &Frames::default(),
        Angle::from_deg(90.0),
        [1.0, 2.0, 3.0],
        Time::default(),
    );
    let t = &tf.transforms[0];
    assert_eq!(
        (t.header.frame_id.as_str(), t.child_frame_id.as_str()),
        ("map", "lightpose_beacon")
    );
    assert_eq!(
        t.transform.translation,
        Vector3 {
            x: 2.0,
            y: 1.0,
            z: -3.0
        }
    );
    assert!(t.transform.rotation.z.abs() < 1e-12 && (t.transform.rotation.w - 1.0).abs() < 1e-12);
    // North (0°): x_B is ENU's +y, a quarter turn.
    let r = rotation(
        &site_tf(&Frames::default(), Angle::ZERO, [0.0; 3], Time::default()).transforms[0]
            .transform
            .rotation,
    );
    assert!((r[1][0] - 1.0).abs() < 1e-12, "{r:?}");
}
