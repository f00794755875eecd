//! Embree 3 as a reference caster ([`EmbreeCaster`]): the scene's triangles and the same
//! segments through `rtcOccluded1`, `rtcOccluded1M` and `rtcIntersect1`, so that `raybench`
//! can time Embree in turns with our casters ([`turns`](super::turns)) and its ratios hold
//! while the machine's speed drifts. The library is loaded at run time (`libembree3.so.3`,
//! Debian's `libembree3-3`): hirad builds and runs without it.

use super::turns::TurnCaster;
use super::Segment;
use hirad_core::{Error, Result};
use hirad_scene::Scene;
use libloading::Library;
use rayon::prelude::*;
use std::ffi::{c_char, c_void};
use std::time::Instant;

type Handle = *mut c_void;

/// `struct RTCRay`.
#[repr(C, align(16))]
#[derive(Clone, Copy)]
struct Ray {
    org: [f32; 3],
    tnear: f32,
    dir: [f32; 3],
    time: f32,
    tfar: f32,
    mask: u32,
    id: u32,
    flags: u32,
}

/// `struct RTCHit` (one instance level, as Embree is built by default).
#[repr(C, align(16))]
#[derive(Clone, Copy)]
struct HitRec {
    ng: [f32; 3],
    u: f32,
    v: f32,
    prim_id: u32,
    geom_id: u32,
    inst_id: [u32; 1],
}

/// `struct RTCRayHit`.
#[repr(C)]
struct RayHit {
    ray: Ray,
    hit: HitRec,
}

/// `struct RTCIntersectContext` as `rtcInitIntersectContext` fills it (one instance level).
#[repr(C)]
struct Context {
    flags: u32,
    filter: *const c_void,
    inst_id: [u32; 1],
}

const INVALID_ID: u32 = u32::MAX;
const GEOMETRY_TYPE_TRIANGLE: i32 = 0;
const BUFFER_TYPE_INDEX: i32 = 0;
const BUFFER_TYPE_VERTEX: i32 = 1;
const FORMAT_UINT3: i32 = 0x5003;
const FORMAT_FLOAT3: i32 = 0x9003;
const SCENE_FLAG_ROBUST: i32 = 1 << 2;
const CONTEXT_FLAG_INCOHERENT: u32 = 0;
/// Rays per `rtcOccluded1M` call of the batch query.
const STREAM_CHUNK: usize = 256;

impl Context {
    fn new(flags: u32) -> Context {
        Context {
            flags,
            filter: std::ptr::null(),
            inst_id: [INVALID_ID],
        }
    }
}

impl Ray {
    const EMPTY: Ray = Ray {
        org: [0.0; 3],
        tnear: 0.0,
        dir: [0.0; 3],
        time: 0.0,
        tfar: 0.0,
        mask: 0,
        id: 0,
        flags: 0,
    };

    fn new(s: &Segment) -> Ray {
        Ray {
            org: s.origin.to_array(),
            tnear: s.tmin,
            dir: s.dir.to_array(),
            time: 0.0,
            tfar: s.tmax,
            mask: u32::MAX,
            id: 0,
            flags: 0,
        }
    }

    /// After an occlusion query: Embree sets `tfar` to −∞ on a hit.
    fn occluded(&self) -> bool {
        self.tfar < 0.0
    }
}

/// The entry points used, resolved once.
struct Api {
    new_device: unsafe extern "C" fn(*const c_char) -> Handle,
    release_device: unsafe extern "C" fn(Handle),
    get_device_error: unsafe extern "C" fn(Handle) -> i32,
    new_scene: unsafe extern "C" fn(Handle) -> Handle,
    set_scene_flags: unsafe extern "C" fn(Handle, i32),
    new_geometry: unsafe extern "C" fn(Handle, i32) -> Handle,
    set_new_geometry_buffer:
        unsafe extern "C" fn(Handle, i32, u32, i32, usize, usize) -> *mut c_void,
    commit_geometry: unsafe extern "C" fn(Handle),
    attach_geometry: unsafe extern "C" fn(Handle, Handle) -> u32,
    release_geometry: unsafe extern "C" fn(Handle),
    commit_scene: unsafe extern "C" fn(Handle),
    release_scene: unsafe extern "C" fn(Handle),
    occluded1: unsafe extern "C" fn(Handle, *mut Context, *mut Ray),
    occluded1m: unsafe extern "C" fn(Handle, *mut Context, *mut Ray, u32, usize),
    intersect1: unsafe extern "C" fn(Handle, *mut Context, *mut RayHit),
    /// Keeps the entry points valid. Never unloaded: Embree's worker threads outlive its
    /// devices, and unloading the code under them crashes the process at exit.
    _lib: Library,
}

impl Api {
    /// The library, loaded once per process.
    fn get() -> Result<&'static Api> {
        static API: std::sync::OnceLock<std::result::Result<Api, String>> =
            std::sync::OnceLock::new();
        API.get_or_init(|| Api::load().map_err(|e| e.to_string()))
            .as_ref()
            .map_err(|e| Error::Config(e.clone()))
    }

    fn load() -> Result<Api> {
        let names = [
            "libembree3.so.3".to_string(),
            libloading::library_filename("embree3")
                .to_string_lossy()
                .into_owned(),
        ];
        // SAFETY: loading Embree runs no initialiser beyond its C++ statics.
        let lib = names
            .iter()
            .find_map(|n| unsafe { Library::new(n) }.ok())
            .ok_or_else(|| {
                Error::Config(format!(
                    "Embree 3 not found ({}): install it (Debian, Ubuntu: apt-get install \
                     libembree3-3) or leave out --embree",
                    names.join(", ")
                ))
            })?;
        macro_rules! sym {
            ($name:literal) => {
                // SAFETY: the symbol has the type of Embree 3's declaration (rtcore_*.h).
                *unsafe { lib.get($name) }.map_err(|e| {
                    Error::Config(format!("Embree 3 library without an entry point: {e}"))
                })?
            };
        }
        Ok(Api {
            new_device: sym!(b"rtcNewDevice\0"),
            release_device: sym!(b"rtcReleaseDevice\0"),
            get_device_error: sym!(b"rtcGetDeviceError\0"),
            new_scene: sym!(b"rtcNewScene\0"),
            set_scene_flags: sym!(b"rtcSetSceneFlags\0"),
            new_geometry: sym!(b"rtcNewGeometry\0"),
            set_new_geometry_buffer: sym!(b"rtcSetNewGeometryBuffer\0"),
            commit_geometry: sym!(b"rtcCommitGeometry\0"),
            attach_geometry: sym!(b"rtcAttachGeometry\0"),
            release_geometry: sym!(b"rtcReleaseGeometry\0"),
            commit_scene: sym!(b"rtcCommitScene\0"),
            release_scene: sym!(b"rtcReleaseScene\0"),
            occluded1: sym!(b"rtcOccluded1\0"),
            occluded1m: sym!(b"rtcOccluded1M\0"),
            intersect1: sym!(b"rtcIntersect1\0"),
            _lib: lib,
        })
    }
}

/// A scene committed to Embree 3 (default build quality, one build thread), queried from
/// any thread.
pub struct EmbreeCaster {
    api: &'static Api,
    device: Handle,
    scene: Handle,
    /// Seconds `rtcCommitScene` took (the build).
    pub build_s: f64,
    /// Whether the scene was built with `RTC_SCENE_FLAG_ROBUST`.
    pub robust: bool,
}

// SAFETY: Embree's queries on a committed scene are thread-safe; the handles are only
// released in `drop`.
unsafe impl Send for EmbreeCaster {}
// SAFETY: as above.
unsafe impl Sync for EmbreeCaster {}

impl EmbreeCaster {
    /// Load Embree and commit the triangles of `scene` (three vertices each, unshared, as
    /// `benches/embree/occluded.c` does). `robust`: `RTC_SCENE_FLAG_ROBUST`.
    pub fn new(scene: &Scene, robust: bool) -> Result<EmbreeCaster> {
        let api = Api::get()?;
        let n = scene.num_triangles();
        let fail = |what: &str| Error::Config(format!("Embree 3: {what} failed"));
        // SAFETY: calls as Embree 3's API documents them; buffers are written within the
        // sizes they were created with.
        unsafe {
            let device = (api.new_device)(c"threads=1".as_ptr());
            if device.is_null() {
                return Err(fail("rtcNewDevice"));
            }
            let mut c = EmbreeCaster {
                api,
                device,
                scene: std::ptr::null_mut(),
                build_s: 0.0,
                robust,
            };
            let a = &c.api;
            c.scene = (a.new_scene)(device);
            if c.scene.is_null() {
                return Err(fail("rtcNewScene"));
            }
            if robust {
                (a.set_scene_flags)(c.scene, SCENE_FLAG_ROBUST);
            }
            let g = (a.new_geometry)(device, GEOMETRY_TYPE_TRIANGLE);
            if g.is_null() {
                return Err(fail("rtcNewGeometry"));
            }
            let vb = (a.set_new_geometry_buffer)(g, BUFFER_TYPE_VERTEX, 0, FORMAT_FLOAT3, 12, 3 * n)
                as *mut [f32; 3];
            let ib = (a.set_new_geometry_buffer)(g, BUFFER_TYPE_INDEX, 0, FORMAT_UINT3, 12, n)
                as *mut [u32; 3];
            if vb.is_null() || ib.is_null() {
                (a.release_geometry)(g);
                return Err(fail("rtcSetNewGeometryBuffer"));
            }
            for i in 0..n {
                let k = 3 * i as u32;
                for (j, p) in scene.tri_vertices(i).iter().enumerate() {
                    vb.add(3 * i + j).write(p.to_array());
                }
                ib.add(i).write([k, k + 1, k + 2]);
            }
            (a.commit_geometry)(g);
            (a.attach_geometry)(c.scene, g);
            (a.release_geometry)(g);
            let t0 = Instant::now();
            (a.commit_scene)(c.scene);
            c.build_s = t0.elapsed().as_secs_f64();
            let err = (a.get_device_error)(device);
            if err != 0 {
                return Err(Error::Config(format!(
                    "Embree 3: building the scene failed (RTCError {err})"
                )));
            }
            Ok(c)
        }
    }

    /// Occlusion of one segment (`rtcOccluded1`).
    pub fn occluded(&self, s: &Segment) -> bool {
        let mut ctx = Context::new(CONTEXT_FLAG_INCOHERENT);
        let mut r = Ray::new(s);
        // SAFETY: a committed scene, a valid context and ray.
        unsafe { (self.api.occluded1)(self.scene, &mut ctx, &mut r) };
        r.occluded()
    }

    /// Occluded segments of `segs` on the calling thread, as streams of [`STREAM_CHUNK`] rays
    /// (`rtcOccluded1M`, flagged incoherent: on the solver's rays Embree's coherent mode is
    /// slower than its single queries).
    fn stream_count(&self, segs: &[Segment]) -> u64 {
        let mut rays = [Ray::EMPTY; STREAM_CHUNK];
        let mut ctx = Context::new(CONTEXT_FLAG_INCOHERENT);
        let mut hits = 0;
        for c in segs.chunks(STREAM_CHUNK) {
            for (r, s) in rays.iter_mut().zip(c) {
                *r = Ray::new(s);
            }
            let m = c.len();
            // SAFETY: `m` rays of stride `size_of::<Ray>()` in `rays`.
            unsafe {
                (self.api.occluded1m)(
                    self.scene,
                    &mut ctx,
                    rays.as_mut_ptr(),
                    m as u32,
                    std::mem::size_of::<Ray>(),
                )
            };
            hits += rays[..m].iter().filter(|r| r.occluded()).count() as u64;
        }
        hits
    }

    /// Whether the segment hits a triangle (`rtcIntersect1`).
    pub fn hits(&self, s: &Segment) -> bool {
        let mut ctx = Context::new(CONTEXT_FLAG_INCOHERENT);
        let mut rh = RayHit {
            ray: Ray::new(s),
            hit: HitRec {
                ng: [0.0; 3],
                u: 0.0,
                v: 0.0,
                prim_id: INVALID_ID,
                geom_id: INVALID_ID,
                inst_id: [INVALID_ID],
            },
        };
        // SAFETY: a committed scene, a valid context and ray-hit record.
        unsafe { (self.api.intersect1)(self.scene, &mut ctx, &mut rh) };
        rh.hit.geom_id != INVALID_ID
    }
}

impl TurnCaster for EmbreeCaster {
    fn count_occluded(&self, segs: &[Segment]) -> u64 {
        segs.par_chunks(STREAM_CHUNK * 4)
            .map(|c| self.stream_count(c))
            .sum()
    }

    fn count_occluded_single(&self, segs: &[Segment]) -> u64 {
        segs.par_iter()
            .with_min_len(256)
            .filter(|s| self.occluded(s))
            .count() as u64
    }

    fn count_hits(&self, segs: &[Segment]) -> u64 {
        segs.par_iter()
            .with_min_len(256)
            .filter(|s| self.hits(s))
            .count() as u64
    }
}

impl Drop for EmbreeCaster {
    fn drop(&mut self) {
        // SAFETY: handles created in `new`, released once.
        unsafe {
            if !self.scene.is_null() {
                (self.api.release_scene)(self.scene);
            }
            (self.api.release_device)(self.device);
        }
    }
}
