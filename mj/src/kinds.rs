//! Typed MuJoCo kinds: the geom, sensor, transmission, bias and integrator enums of the C API
//! (`mjtGeom`, `mjtSensor`, `mjtTrn`, `mjtBias`, `mjtIntegrator`) as Rust enums, so that code
//! outside `mj` matches on names instead of raw `mujoco_sys` constants. Each is read from the
//! model's integer arrays by [`Model`](super::Model) (`geom_kind`, `sensor_kind`, …); a value
//! this wrapper does not name comes back as `Other(raw)`, never a panic.

use mujoco_sys as sys;

/// Declares a kind enum, its raw value (`raw`) and the mapping back (`from_raw`), from one table
/// of `Variant = sys constant` lines; values outside the table map to `Other(raw)`.
macro_rules! mj_kind {
    ($(#[$doc:meta])* $name:ident { $($(#[$vdoc:meta])* $variant:ident = $raw:path,)+ }) => {
        $(#[$doc])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq)]
        pub enum $name {
            $($(#[$vdoc])* $variant,)+
            /// A value this wrapper does not name (the raw MuJoCo integer).
            Other(i32),
        }

        impl $name {
            /// The kind of MuJoCo's integer `raw`.
            pub fn from_raw(raw: i32) -> Self {
                $(if raw == $raw as i32 {
                    return $name::$variant;
                })+
                $name::Other(raw)
            }

            /// MuJoCo's integer for this kind.
            pub fn raw(self) -> i32 {
                match self {
                    $($name::$variant => $raw as i32,)+
                    $name::Other(raw) => raw,
                }
            }
        }
    };
}

mj_kind! {
    /// Geometric type of a geom (`mjtGeom`).
    GeomType {
        /// `mjGEOM_PLANE`: infinite plane, `size[2]` grid spacing.
        Plane = sys::mjtGeom_mjGEOM_PLANE,
        /// `mjGEOM_HFIELD`: height field.
        Hfield = sys::mjtGeom_mjGEOM_HFIELD,
        /// `mjGEOM_SPHERE`: `size[0]` radius.
        Sphere = sys::mjtGeom_mjGEOM_SPHERE,
        /// `mjGEOM_CAPSULE`: `size[0]` radius, `size[1]` half-length along z.
        Capsule = sys::mjtGeom_mjGEOM_CAPSULE,
        /// `mjGEOM_ELLIPSOID`: `size[0..3]` semi-axes.
        Ellipsoid = sys::mjtGeom_mjGEOM_ELLIPSOID,
        /// `mjGEOM_CYLINDER`: `size[0]` radius, `size[1]` half-length along z.
        Cylinder = sys::mjtGeom_mjGEOM_CYLINDER,
        /// `mjGEOM_BOX`: `size[0..3]` half-sizes.
        Box = sys::mjtGeom_mjGEOM_BOX,
        /// `mjGEOM_MESH`: a mesh asset.
        Mesh = sys::mjtGeom_mjGEOM_MESH,
        /// `mjGEOM_SDF`: a signed distance field.
        Sdf = sys::mjtGeom_mjGEOM_SDF,
    }
}

mj_kind! {
    /// What a sensor measures (`mjtSensor`); the kinds twin reads by name.
    SensorType {
        /// `mjSENS_TOUCH`
        Touch = sys::mjtSensor_mjSENS_TOUCH,
        /// `mjSENS_ACCELEROMETER`: specific force in the site frame, m/s².
        Accelerometer = sys::mjtSensor_mjSENS_ACCELEROMETER,
        /// `mjSENS_VELOCIMETER`
        Velocimeter = sys::mjtSensor_mjSENS_VELOCIMETER,
        /// `mjSENS_GYRO`: angular velocity in the site frame, rad/s.
        Gyro = sys::mjtSensor_mjSENS_GYRO,
        /// `mjSENS_FORCE`
        Force = sys::mjtSensor_mjSENS_FORCE,
        /// `mjSENS_TORQUE`
        Torque = sys::mjtSensor_mjSENS_TORQUE,
        /// `mjSENS_RANGEFINDER`
        Rangefinder = sys::mjtSensor_mjSENS_RANGEFINDER,
        /// `mjSENS_JOINTPOS`: a joint's position, rad or m.
        JointPos = sys::mjtSensor_mjSENS_JOINTPOS,
        /// `mjSENS_JOINTVEL`: a joint's velocity, rad/s or m/s.
        JointVel = sys::mjtSensor_mjSENS_JOINTVEL,
        /// `mjSENS_FRAMEPOS`
        FramePos = sys::mjtSensor_mjSENS_FRAMEPOS,
        /// `mjSENS_FRAMEQUAT`: an object's orientation, quaternion w x y z.
        FrameQuat = sys::mjtSensor_mjSENS_FRAMEQUAT,
    }
}

mj_kind! {
    /// How an actuator transmits its force (`mjtTrn`).
    Transmission {
        /// `mjTRN_JOINT`: onto one joint.
        Joint = sys::mjtTrn_mjTRN_JOINT,
        /// `mjTRN_JOINTINPARENT`
        JointInParent = sys::mjtTrn_mjTRN_JOINTINPARENT,
        /// `mjTRN_SLIDERCRANK`
        SliderCrank = sys::mjtTrn_mjTRN_SLIDERCRANK,
        /// `mjTRN_TENDON`
        Tendon = sys::mjtTrn_mjTRN_TENDON,
        /// `mjTRN_SITE`
        Site = sys::mjtTrn_mjTRN_SITE,
        /// `mjTRN_BODY`
        Body = sys::mjtTrn_mjTRN_BODY,
    }
}

mj_kind! {
    /// An actuator's bias force (`mjtBias`).
    BiasType {
        /// `mjBIAS_NONE`
        None = sys::mjtBias_mjBIAS_NONE,
        /// `mjBIAS_AFFINE`: `b0 + b1·length + b2·velocity` (position and velocity servos).
        Affine = sys::mjtBias_mjBIAS_AFFINE,
        /// `mjBIAS_MUSCLE`
        Muscle = sys::mjtBias_mjBIAS_MUSCLE,
        /// `mjBIAS_DCMOTOR`: back-EMF (and cogging, LuGre friction) of a `dcmotor`.
        Dcmotor = sys::mjtBias_mjBIAS_DCMOTOR,
        /// `mjBIAS_USER`
        User = sys::mjtBias_mjBIAS_USER,
    }
}

mj_kind! {
    /// Activation dynamics of an actuator (`mjtDyn`).
    DynType {
        /// `mjDYN_NONE`: stateless.
        None = sys::mjtDyn_mjDYN_NONE,
        /// `mjDYN_INTEGRATOR`
        Integrator = sys::mjtDyn_mjDYN_INTEGRATOR,
        /// `mjDYN_FILTER`
        Filter = sys::mjtDyn_mjDYN_FILTER,
        /// `mjDYN_FILTEREXACT`
        FilterExact = sys::mjtDyn_mjDYN_FILTEREXACT,
        /// `mjDYN_MUSCLE`
        Muscle = sys::mjtDyn_mjDYN_MUSCLE,
        /// `mjDYN_DCMOTOR`: a `dcmotor` (`gainprm`: R, K, …, kp, ki, kd, Vmax at 4..8).
        Dcmotor = sys::mjtDyn_mjDYN_DCMOTOR,
        /// `mjDYN_PID`
        Pid = sys::mjtDyn_mjDYN_PID,
        /// `mjDYN_USER`
        User = sys::mjtDyn_mjDYN_USER,
    }
}

mj_kind! {
    /// The numerical integrator (`mjtIntegrator`).
    Integrator {
        /// `mjINT_EULER`: semi-implicit Euler.
        Euler = sys::mjtIntegrator_mjINT_EULER,
        /// `mjINT_RK4`: 4th-order Runge-Kutta (no `mj_step1`/`mj_step2` split).
        Rk4 = sys::mjtIntegrator_mjINT_RK4,
        /// `mjINT_IMPLICIT`
        Implicit = sys::mjtIntegrator_mjINT_IMPLICIT,
        /// `mjINT_IMPLICITFAST`
        ImplicitFast = sys::mjtIntegrator_mjINT_IMPLICITFAST,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn raw_values_round_trip_and_unknown_ones_are_other() {
        for g in [GeomType::Plane, GeomType::Box, GeomType::Mesh, GeomType::Sdf] {
            assert_eq!(GeomType::from_raw(g.raw()), g);
        }
        assert_eq!(GeomType::from_raw(6), GeomType::Box);
        assert_eq!(SensorType::from_raw(3), SensorType::Gyro);
        assert_eq!(SensorType::from_raw(27), SensorType::FrameQuat);
        assert_eq!(Transmission::from_raw(0), Transmission::Joint);
        assert_eq!(BiasType::from_raw(1), BiasType::Affine);
        assert_eq!(Integrator::from_raw(1), Integrator::Rk4);
        assert_eq!(GeomType::from_raw(1001), GeomType::Other(1001));
        assert_eq!(GeomType::Other(1001).raw(), 1001);
    }
}
