use super::*;
use glam::Quat;
use rapier3d::parry::shape::{Capsule, Shape as ParryShape};

/// The f64 local frame against parry's own posed queries, for rotated shapes: the same
/// surface point and normal within f32 rounding, inside and outside, and along a cast path.
#[test]
fn local_frame_queries_match_posed_queries() {
    let pose = Pose::from_parts(
        Vec3::new(0.3, -1.2, 2.0),
        Quat::from_euler(glam::EulerRot::XYZ, 0.7, -0.4, 1.1),
    );
    let cuboid = Cuboid::new(Vec3::new(0.5, 0.2, 0.8));
    let capsule = Capsule::new_y(0.6, 0.25);
    let ball = Ball::new(0.4);
    let points = [
        DVec3::new(0.9, -0.9, 2.4),
        DVec3::new(0.35, -1.15, 2.05),
        DVec3::new(-0.2, -1.6, 1.5),
        DVec3::new(0.3, -0.6, 2.3),
    ];
    let check = |shape: &dyn ParryShape, symmetric: bool| {
        let frame = Local::of(&pose, symmetric);
        for &x in &points {
            let posed = shape.project_point(&pose, x.as_vec3(), false);
            let hit = surface(shape, &frame, x, x, false, 10.0).unwrap();
            assert!((hit.point - posed.point.as_dvec3()).length() < 1e-5, "{x}");
            let dist = (x - hit.point).length();
            assert!((hit.depth > 0.0) == posed.is_inside && dist > 1e-3);
            let outward = if posed.is_inside {
                hit.point - x
            } else {
                x - hit.point
            };
            assert!((hit.normal - outward / dist).length() < 1e-5);
        }
        // A path from far outside through the shape's centre: the swept test meets the
        // surface where parry's posed ray cast does.
        let (x0, x1) = (DVec3::new(3.0, 1.0, 4.0), pose.translation.as_dvec3());
        let hit = surface(shape, &frame, x0, x1, true, 1e-3).unwrap();
        let ray = Ray::new(x0.as_vec3(), (x1 - x0).as_vec3());
        let r = shape
            .cast_ray_and_get_normal(&pose, &ray, 1.0, false)
            .unwrap();
        assert!(hit.swept);
        let at = x0 + (x1 - x0) * r.time_of_impact as f64;
        assert!((hit.point - at).length() < 1e-5);
        assert!((hit.normal - r.normal.as_dvec3()).length() < 1e-5);
    };
    check(&cuboid, false);
    check(&capsule, false);
    check(&ball, true);
    check(&ball, false);
}
