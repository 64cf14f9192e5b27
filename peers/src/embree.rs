//! The few Embree 3 calls the comparison needs (Embree 3.13, the C API of
//! `rtcore.h`), behind a safe wrapper: a triangle scene and single-ray
//! closest-hit queries (`rtcIntersect1`), coherent packets of eight
//! (`rtcIntersect8`) and occlusion queries (`rtcOccluded1`).

use std::ffi::{c_char, c_void};

type Device = *mut c_void;
type Scene = *mut c_void;
type Geometry = *mut c_void;

const GEOMETRY_TYPE_TRIANGLE: u32 = 0;
const BUFFER_TYPE_INDEX: u32 = 0;
const BUFFER_TYPE_VERTEX: u32 = 1;
const FORMAT_UINT3: u32 = 0x5003;
const FORMAT_FLOAT3: u32 = 0x9003;
const INVALID_ID: u32 = u32::MAX;

/// `struct RTCIntersectContext` (RTC_MAX_INSTANCE_LEVEL_COUNT = 1,
/// RTC_MIN_WIDTH = 0 in Debian's build).
#[repr(C)]
struct IntersectContext {
    flags: u32,
    filter: *const c_void,
    inst_id: [u32; 1],
}

/// `struct RTCRayHit` (RTCRay then RTCHit, 16-byte aligned).
#[repr(C, align(16))]
#[derive(Clone, Copy)]
struct RayHit {
    org: [f32; 3],
    tnear: f32,
    dir: [f32; 3],
    time: f32,
    tfar: f32,
    mask: u32,
    id: u32,
    flags: u32,
    ng: [f32; 3],
    u: f32,
    v: f32,
    prim_id: u32,
    geom_id: u32,
    inst_id: [u32; 1],
}

/// `struct RTCRayHit8` (RTCRay8 then RTCHit8, structure of arrays,
/// 32-byte aligned).
#[repr(C, align(32))]
#[derive(Clone, Copy)]
struct RayHit8 {
    org_x: [f32; 8],
    org_y: [f32; 8],
    org_z: [f32; 8],
    tnear: [f32; 8],
    dir_x: [f32; 8],
    dir_y: [f32; 8],
    dir_z: [f32; 8],
    time: [f32; 8],
    tfar: [f32; 8],
    mask: [u32; 8],
    id: [u32; 8],
    flags: [u32; 8],
    ng_x: [f32; 8],
    ng_y: [f32; 8],
    ng_z: [f32; 8],
    u: [f32; 8],
    v: [f32; 8],
    prim_id: [u32; 8],
    geom_id: [u32; 8],
    inst_id: [[u32; 8]; 1],
}

/// `struct RTCRay` (the ray part of [`RayHit`]).
#[repr(C, align(16))]
#[derive(Clone, Copy)]
struct Ray1 {
    org: [f32; 3],
    tnear: f32,
    dir: [f32; 3],
    time: f32,
    tfar: f32,
    mask: u32,
    id: u32,
    flags: u32,
}

/// An `f32` ray as Embree takes it: origin, direction, `t` range.
pub type EmbreeRay = ([f32; 3], [f32; 3], f32, f32);

#[link(name = "embree3")]
unsafe extern "C" {
    fn rtcNewDevice(config: *const c_char) -> Device;
    fn rtcReleaseDevice(device: Device);
    fn rtcNewScene(device: Device) -> Scene;
    fn rtcReleaseScene(scene: Scene);
    fn rtcCommitScene(scene: Scene);
    fn rtcNewGeometry(device: Device, kind: u32) -> Geometry;
    fn rtcSetNewGeometryBuffer(
        geometry: Geometry,
        kind: u32,
        slot: u32,
        format: u32,
        byte_stride: usize,
        item_count: usize,
    ) -> *mut c_void;
    fn rtcCommitGeometry(geometry: Geometry);
    fn rtcAttachGeometry(scene: Scene, geometry: Geometry) -> u32;
    fn rtcReleaseGeometry(geometry: Geometry);
    fn rtcIntersect1(scene: Scene, context: *mut IntersectContext, rayhit: *mut RayHit);
    fn rtcIntersect8(
        valid: *const i32,
        scene: Scene,
        context: *mut IntersectContext,
        rayhit: *mut RayHit8,
    );
    fn rtcOccluded1(scene: Scene, context: *mut IntersectContext, ray: *mut Ray1);
}

fn context() -> IntersectContext {
    IntersectContext {
        flags: 0,
        filter: std::ptr::null(),
        inst_id: [INVALID_ID],
    }
}

/// An Embree device and a committed triangle scene.
pub struct EmbreeScene {
    device: Device,
    scene: Scene,
}

// SAFETY: Embree documents rtcIntersect1 on a committed scene as
// thread-safe; the handles are only released in Drop.
unsafe impl Send for EmbreeScene {}
// SAFETY: as above.
unsafe impl Sync for EmbreeScene {}

impl EmbreeScene {
    /// Builds the scene from positions and triangle indices; `config` is
    /// Embree's device configuration (e.g. `threads=1`).
    pub fn new(
        positions: &[[f32; 3]],
        tris: &[[u32; 3]],
        config: &str,
    ) -> anyhow::Result<EmbreeScene> {
        let config = std::ffi::CString::new(config)?;
        // SAFETY: plain C calls with valid arguments; the buffers Embree
        // returns have the requested size (plus the 16 bytes of padding it
        // documents for vertex buffers), checked non-null before use.
        unsafe {
            let device = rtcNewDevice(config.as_ptr());
            anyhow::ensure!(!device.is_null(), "rtcNewDevice failed");
            let scene = rtcNewScene(device);
            let geom = rtcNewGeometry(device, GEOMETRY_TYPE_TRIANGLE);
            let v = rtcSetNewGeometryBuffer(
                geom,
                BUFFER_TYPE_VERTEX,
                0,
                FORMAT_FLOAT3,
                12,
                positions.len(),
            )
            .cast::<[f32; 3]>();
            let i =
                rtcSetNewGeometryBuffer(geom, BUFFER_TYPE_INDEX, 0, FORMAT_UINT3, 12, tris.len())
                    .cast::<[u32; 3]>();
            anyhow::ensure!(
                !v.is_null() && !i.is_null(),
                "rtcSetNewGeometryBuffer failed"
            );
            std::ptr::copy_nonoverlapping(positions.as_ptr(), v, positions.len());
            std::ptr::copy_nonoverlapping(tris.as_ptr(), i, tris.len());
            rtcCommitGeometry(geom);
            rtcAttachGeometry(scene, geom);
            rtcReleaseGeometry(geom);
            rtcCommitScene(scene);
            Ok(EmbreeScene { device, scene })
        }
    }

    /// The closest hit: (triangle index, t), or `None`.
    #[inline]
    pub fn intersect(
        &self,
        origin: [f32; 3],
        dir: [f32; 3],
        t_min: f32,
        t_max: f32,
    ) -> Option<(u32, f32)> {
        let mut ctx = context();
        let mut rh = RayHit {
            org: origin,
            tnear: t_min,
            dir,
            time: 0.0,
            tfar: t_max,
            mask: u32::MAX,
            id: 0,
            flags: 0,
            ng: [0.0; 3],
            u: 0.0,
            v: 0.0,
            prim_id: INVALID_ID,
            geom_id: INVALID_ID,
            inst_id: [INVALID_ID],
        };
        // SAFETY: the scene is committed; ctx and rh are valid for the call.
        unsafe { rtcIntersect1(self.scene, &raw mut ctx, &raw mut rh) };
        (rh.geom_id != INVALID_ID).then_some((rh.prim_id, rh.tfar))
    }

    /// Closest hits of up to eight rays traced as one coherent packet
    /// (`rtcIntersect8`, the rays of `rays` valid, the other lanes not).
    pub fn intersect8(&self, rays: &[EmbreeRay]) -> [Option<(u32, f32)>; 8] {
        let mut rh = RayHit8 {
            org_x: [0.0; 8],
            org_y: [0.0; 8],
            org_z: [0.0; 8],
            tnear: [0.0; 8],
            dir_x: [0.0; 8],
            dir_y: [0.0; 8],
            dir_z: [1.0; 8],
            time: [0.0; 8],
            tfar: [-1.0; 8],
            mask: [u32::MAX; 8],
            id: [0; 8],
            flags: [0; 8],
            ng_x: [0.0; 8],
            ng_y: [0.0; 8],
            ng_z: [0.0; 8],
            u: [0.0; 8],
            v: [0.0; 8],
            prim_id: [INVALID_ID; 8],
            geom_id: [INVALID_ID; 8],
            inst_id: [[INVALID_ID; 8]],
        };
        // Embree reads the mask with aligned vector loads: it must be
        // 32-byte aligned like the rays (a plain `[i32; 8]` happened to be
        // until fat LTO moved it, and `rtcIntersect8` then crashed).
        #[repr(C, align(32))]
        struct Valid([i32; 8]);
        let mut valid = Valid([0; 8]);
        let valid = &mut valid.0;
        for (k, &(o, d, t0, t1)) in rays.iter().take(8).enumerate() {
            valid[k] = -1;
            (rh.org_x[k], rh.org_y[k], rh.org_z[k]) = (o[0], o[1], o[2]);
            (rh.dir_x[k], rh.dir_y[k], rh.dir_z[k]) = (d[0], d[1], d[2]);
            (rh.tnear[k], rh.tfar[k]) = (t0, t1);
        }
        let mut ctx = context();
        // SAFETY: the scene is committed; valid, ctx and rh (32-byte
        // aligned, as the API requires) are valid for the call.
        unsafe { rtcIntersect8(valid.as_ptr(), self.scene, &raw mut ctx, &raw mut rh) };
        std::array::from_fn(|k| {
            (valid[k] != 0 && rh.geom_id[k] != INVALID_ID).then_some((rh.prim_id[k], rh.tfar[k]))
        })
    }

    /// `true` when something lies on the ray within its `t` range
    /// (`rtcOccluded1`: any hit, early exit).
    #[inline]
    pub fn occluded(&self, origin: [f32; 3], dir: [f32; 3], t_min: f32, t_max: f32) -> bool {
        let mut ctx = context();
        let mut r = Ray1 {
            org: origin,
            tnear: t_min,
            dir,
            time: 0.0,
            tfar: t_max,
            mask: u32::MAX,
            id: 0,
            flags: 0,
        };
        // SAFETY: the scene is committed; ctx and r are valid for the call.
        unsafe { rtcOccluded1(self.scene, &raw mut ctx, &raw mut r) };
        r.tfar == f32::NEG_INFINITY
    }
}

impl Drop for EmbreeScene {
    fn drop(&mut self) {
        // SAFETY: released once, after every use.
        unsafe {
            rtcReleaseScene(self.scene);
            rtcReleaseDevice(self.device);
        }
    }
}
