//! Frames, box geometry and the one conversion from the BoxED Unity frame to the box frame B.
//!
//! **Box frame B**: right-handed, z up, metres, origin at the centre of the box's inner floor,
//! x along the long side. Inner volume: `|x| <= BOX_HALF_X`, `|y| <= BOX_HALF_Y`,
//! `0 <= z <= BOX_HEIGHT`. Numbers from `../shared/boxed/README.md` ("Frames", "Box").
//!
//! The BoxED data is Unity (left-handed, y up). [`unity_place_to_box`] is the only place where
//! it is converted; everything downstream of the loader works in B.

use parry3d::math::{Mat3, Rotation, Vector};

/// Inner half-length of the box along B x (m).
pub const BOX_HALF_X: f32 = 0.17306;
/// Inner half-width of the box along B y (m).
pub const BOX_HALF_Y: f32 = 0.11382;
/// Inner height of the box, floor to rim (m).
pub const BOX_HEIGHT: f32 = 0.16390;
/// Thickness of the floor and walls (m), about 1.57 cm in the BoxED prefab.
pub const BOX_WALL_THICKNESS: f32 = 0.0157;
/// Vertical margin above the rim that still counts as inside (m), as in the HERB paper
/// ("a vertical margin of 13 cm is added to the successful placement bounding box").
pub const SUCCESS_MARGIN_Z: f32 = 0.13;
/// Top of the success volume (m): rim plus margin.
pub const SUCCESS_TOP_Z: f32 = BOX_HEIGHT + SUCCESS_MARGIN_Z;

/// The default widening of the success volume for contact penetration (m).
pub const INSIDE_TOLERANCE_M: f32 = 0.01;

/// Gap added above an object's estimated resting height before it is released (m): the
/// world's and herbd's default.
pub const RELEASE_CLEARANCE_M: f32 = 0.002;

/// Unity world axes to B axes (B x = world -z, B y = world +x, B z = world +y); det = -1.
const M_UNITY_TO_B: [[f32; 3]; 3] = [[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];

fn mat_from_rows(r: [[f32; 3]; 3]) -> Mat3 {
    // glam matrices are column-major: build from columns.
    Mat3::from_cols(
        Vector::new(r[0][0], r[1][0], r[2][0]),
        Vector::new(r[0][1], r[1][1], r[2][1]),
        Vector::new(r[0][2], r[1][2], r[2][2]),
    )
}

/// A pose of an object's mesh-file frame in B: `vertex_B = rotation * (scale * v_mesh) + translation`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeshPoseB {
    /// Rotation from mesh-file coordinates to B (proper rotation).
    pub rotation: Rotation,
    /// Position of the mesh-file origin (the Unity pivot) in B (m).
    pub translation: Vector,
}

/// Converts one BoxED `PickPlace_dataset.json` placement to B.
///
/// `place_rotation` is the row-major Unity world rotation of the object (`placeRotation`),
/// `place_translation_norm` the pivot in normalised box coordinates (`placeTranslation`).
/// Implements `p_B = [hx lx, hy lz, H ly]` and `R_B = M R F` with `F = diag(-1, 1, 1)`
/// (Unity imports OBJ files with x negated). Returns `None` if the rotation is not a proper
/// rotation within 1e-3 (corrupt data).
pub fn unity_place_to_box(
    place_rotation: [[f32; 3]; 3],
    place_translation_norm: [f32; 3],
) -> Option<MeshPoseB> {
    let l = place_translation_norm;
    let translation = Vector::new(BOX_HALF_X * l[0], BOX_HALF_Y * l[2], BOX_HEIGHT * l[1]);
    let r = mat_from_rows(place_rotation);
    let m = mat_from_rows(M_UNITY_TO_B);
    let f = Mat3::from_diagonal(Vector::new(-1.0, 1.0, 1.0));
    let rb = m * r * f;
    let ortho_err = (rb.transpose() * rb - Mat3::IDENTITY)
        .to_cols_array()
        .iter()
        .fold(0.0f32, |a, v| a.max(v.abs()));
    if !translation.is_finite()
        || !rb.is_finite()
        || !ortho_err.is_finite()
        || ortho_err > 1e-3
        || rb.determinant() < 0.0
    {
        return None;
    }
    Some(MeshPoseB {
        rotation: Rotation::from_mat3(&rb).normalize(),
        translation,
    })
}

/// Twist angle about B z of a rotation (swing-twist decomposition), in (-pi, pi].
pub fn yaw_of(rotation: Rotation) -> f32 {
    let theta = 2.0 * rotation.z.atan2(rotation.w);
    wrap_angle(theta)
}

/// Angle (rad) between the rotated z axis and B z: how far an upright object has tipped.
pub fn tilt_of(rotation: Rotation) -> f32 {
    (rotation * Vector::Z).z.clamp(-1.0, 1.0).acos()
}

/// How far an object released in orientation `release` has tipped once it is in orientation
/// `settled`: the angle (rad) between B z and the object axis that pointed up at release. For a
/// release turned about z only this is [`tilt_of`]`(settled)`, computed exactly so.
pub fn tilt_from(release: Rotation, settled: Rotation) -> f32 {
    if release.x == 0.0 && release.y == 0.0 {
        return tilt_of(settled);
    }
    let up = release.inverse() * Vector::Z;
    (settled * up).z.clamp(-1.0, 1.0).acos()
}

/// Wraps an angle to (-pi, pi].
pub fn wrap_angle(a: f32) -> f32 {
    let tau = std::f32::consts::TAU;
    let mut w = a.rem_euclid(tau);
    if w > std::f32::consts::PI {
        w -= tau;
    }
    w
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identity_unity_rotation_maps_to_mirrored_axes() {
        // Unity identity: R_B = M F, a proper rotation.
        let p = unity_place_to_box(
            [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            [1.0, 0.5, -1.0],
        )
        .expect("valid");
        assert!(
            (p.translation - Vector::new(BOX_HALF_X, -BOX_HALF_Y, 0.5 * BOX_HEIGHT)).length()
                < 1e-6
        );
        // Mesh +y (Unity up) must map to B +z.
        let up = p.rotation * Vector::Y;
        assert!((up - Vector::Z).length() < 1e-6, "{up:?}");
    }

    #[test]
    fn rejects_improper_rotation() {
        assert!(
            unity_place_to_box(
                [[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
                [0.0; 3]
            )
            .is_none()
        );
        assert!(
            unity_place_to_box(
                [[f32::NAN, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
                [0.0; 3]
            )
            .is_none()
        );
    }

    #[test]
    fn yaw_and_tilt() {
        let q = Rotation::from_rotation_z(0.7);
        assert!((yaw_of(q) - 0.7).abs() < 1e-5);
        assert!(tilt_of(q) < 1e-3);
        let t = Rotation::from_rotation_x(0.3) * q;
        assert!((tilt_of(t) - 0.3).abs() < 1e-4);
        assert!((wrap_angle(3.0 * std::f32::consts::PI) - std::f32::consts::PI).abs() < 1e-5);
    }
}
