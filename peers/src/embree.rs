//! The few Embree 3 calls the comparison needs (Embree 3.13, the C API of
//! `rtcore.h`), behind a safe wrapper: a triangle scene and single-ray
//! closest-hit queries (`rtcIntersect1`).

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
        let mut ctx = IntersectContext {
            flags: 0,
            filter: std::ptr::null(),
            inst_id: [INVALID_ID],
        };
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
