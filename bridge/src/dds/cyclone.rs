//! Eclipse Cyclone DDS through its C library (`libddsc`), loaded at run time so the bridge builds
//! and runs without it; asking for this backend on a machine without the library gives a clear
//! error. Built for Cyclone DDS 0.10 (Debian/Ubuntu `libddsc0`; `apt-get install cyclonedds-dev`);
//! the topic descriptors in [`super::cyclone_types`] are generated from the ROS 2 message IDL by
//! `bridge/cyclone/gen_types.sh`. Set `PERTURB_LIBDDSC` to load a specific library file.
//!
//! Writing: the C message struct points at the frame's bytes (no copy); `dds_write` serialises
//! them once into Cyclone's sample and sends it. Reading: `dds_take` with loaned samples; the
//! callback gets a message borrowing Cyclone's buffers, returned right after.
//!
//! Unless `CYCLONEDDS_URI` is set, the participant's domain is created with larger socket buffers
//! and 64 kB datagrams (Cyclone's defaults lose multi-megabyte best-effort samples under load).

// The FFI module: every call into libddsc is unsafe, each block says why it is sound.
#![allow(unsafe_code)]

use super::cyclone_types as ty;
use super::interfaces::Interface;
use super::{DdsBackend, DdsError, DdsReader, DdsWriter, Received, RosType, TopicSpec};
use crate::frame::Payload;
use libloading::Library;
use perturb_core::cloud::{Datatype, PointField};
use perturb_core::formats::ros::{CompressedImageMsg, Header, ImageMsg, PointCloud2Msg};
use std::ffi::{CStr, CString, c_char, c_void};
use std::sync::Arc;
use std::time::Duration;

type Entity = i32;
type Ret = i32;

#[repr(C)]
struct TypeMetaSer {
    data: *const u8,
    sz: u32,
}

#[repr(C)]
struct TopicDescriptor {
    m_size: u32,
    m_align: u32,
    m_flagset: u32,
    m_nkeys: u32,
    m_typename: *const c_char,
    m_keys: *const c_void,
    m_nops: u32,
    m_ops: *const u32,
    m_meta: *const c_char,
    type_information: TypeMetaSer,
    type_mapping: TypeMetaSer,
    restrict_data_representation: u32,
}

// SAFETY: the descriptors point at 'static constants only.
unsafe impl Sync for TopicDescriptor {}

/// `DDS_TOPIC_XTYPES_METADATA`.
const XTYPES_METADATA: u32 = 1 << 6;

macro_rules! descriptor {
    ($name:ident, $m:ident) => {
        static $name: TopicDescriptor = TopicDescriptor {
            m_size: ty::$m::SIZE,
            m_align: ty::$m::ALIGN,
            // Without the XTypes metadata: Cyclone 0.10 crashes in its type lookup when it
            // meets the type objects of newer Cyclone versions (11.x), and ROS 2 matches
            // topics by type name anyway.
            m_flagset: ty::$m::FLAGSET & !XTYPES_METADATA,
            m_nkeys: 0,
            m_typename: ty::$m::TYPENAME.as_ptr(),
            m_keys: std::ptr::null(),
            m_nops: ty::$m::NOPS,
            m_ops: ty::$m::OPS_WORDS.as_ptr(),
            m_meta: c"".as_ptr(),
            type_information: TypeMetaSer {
                data: std::ptr::null(),
                sz: 0,
            },
            type_mapping: TypeMetaSer {
                data: std::ptr::null(),
                sz: 0,
            },
            restrict_data_representation: 0,
        };
    };
}

descriptor!(IMAGE_DESC, image);
descriptor!(COMPRESSED_DESC, compressed_image);
descriptor!(CLOUD_DESC, point_cloud2);

#[repr(C)]
struct Time {
    sec: i32,
    nanosec: u32,
}

#[repr(C)]
struct CHeader {
    stamp: Time,
    frame_id: *mut c_char,
}

#[repr(C)]
struct SeqU8 {
    maximum: u32,
    length: u32,
    buffer: *mut u8,
    release: bool,
}

#[repr(C)]
struct CImage {
    header: CHeader,
    height: u32,
    width: u32,
    encoding: *mut c_char,
    is_bigendian: u8,
    step: u32,
    data: SeqU8,
}

#[repr(C)]
struct CCompressed {
    header: CHeader,
    format: *mut c_char,
    data: SeqU8,
}

#[repr(C)]
struct CPointField {
    name: *mut c_char,
    offset: u32,
    datatype: u8,
    count: u32,
}

#[repr(C)]
struct SeqField {
    maximum: u32,
    length: u32,
    buffer: *mut CPointField,
    release: bool,
}

#[repr(C)]
struct CCloud {
    header: CHeader,
    height: u32,
    width: u32,
    fields: SeqField,
    is_bigendian: bool,
    point_step: u32,
    row_step: u32,
    data: SeqU8,
    is_dense: bool,
}

// The Rust mirrors must match the C layout the descriptors were generated for.
const _: () = {
    assert!(std::mem::size_of::<CImage>() == ty::IMAGE_SIZE);
    assert!(std::mem::offset_of!(CImage, data) == ty::IMAGE_DATA_OFFSET);
    assert!(std::mem::size_of::<CCompressed>() == ty::COMPRESSED_SIZE);
    assert!(std::mem::size_of::<CCloud>() == ty::CLOUD_SIZE);
    assert!(std::mem::offset_of!(CCloud, data) == ty::CLOUD_DATA_OFFSET);
    assert!(std::mem::size_of::<CPointField>() == ty::POINT_FIELD_SIZE);
};

#[repr(C)]
#[derive(Default)]
struct SampleInfo {
    sample_state: u32,
    view_state: u32,
    instance_state: u32,
    valid_data: bool,
    source_timestamp: i64,
    instance_handle: u64,
    publication_handle: u64,
    disposed_generation_count: u32,
    no_writers_generation_count: u32,
    sample_rank: u32,
    generation_rank: u32,
    absolute_generation_rank: u32,
}

#[repr(C)]
#[derive(Default)]
struct PublicationMatched {
    total_count: u32,
    total_count_change: i32,
    current_count: u32,
    current_count_change: i32,
    last_subscription_handle: u64,
}

/// `dds_offered_incompatible_qos_status_t`.
#[repr(C)]
#[derive(Default)]
struct OfferedIncompatibleQos {
    total_count: u32,
    total_count_change: i32,
    last_policy_id: u32,
}

type Qos = c_void;

/// The libddsc functions the backend uses.
struct Api {
    _lib: Library,
    create_domain: unsafe extern "C" fn(u32, *const c_char) -> Entity,
    create_participant: unsafe extern "C" fn(u32, *const Qos, *const c_void) -> Entity,
    create_topic: unsafe extern "C" fn(
        Entity,
        *const TopicDescriptor,
        *const c_char,
        *const Qos,
        *const c_void,
    ) -> Entity,
    create_writer: unsafe extern "C" fn(Entity, Entity, *const Qos, *const c_void) -> Entity,
    create_reader: unsafe extern "C" fn(Entity, Entity, *const Qos, *const c_void) -> Entity,
    create_readcondition: unsafe extern "C" fn(Entity, u32) -> Entity,
    create_waitset: unsafe extern "C" fn(Entity) -> Entity,
    waitset_attach: unsafe extern "C" fn(Entity, Entity, isize) -> Ret,
    waitset_wait: unsafe extern "C" fn(Entity, *mut isize, usize, i64) -> Ret,
    write: unsafe extern "C" fn(Entity, *const c_void) -> Ret,
    take: unsafe extern "C" fn(Entity, *mut *mut c_void, *mut SampleInfo, usize, u32) -> Ret,
    return_loan: unsafe extern "C" fn(Entity, *mut *mut c_void, i32) -> Ret,
    delete: unsafe extern "C" fn(Entity) -> Ret,
    create_qos: unsafe extern "C" fn() -> *mut Qos,
    delete_qos: unsafe extern "C" fn(*mut Qos),
    qset_reliability: unsafe extern "C" fn(*mut Qos, u32, i64),
    qset_history: unsafe extern "C" fn(*mut Qos, u32, i32),
    qset_durability: unsafe extern "C" fn(*mut Qos, u32),
    get_publication_matched_status: unsafe extern "C" fn(Entity, *mut PublicationMatched) -> Ret,
    get_offered_incompatible_qos_status:
        unsafe extern "C" fn(Entity, *mut OfferedIncompatibleQos) -> Ret,
    strretcode: unsafe extern "C" fn(Ret) -> *const c_char,
}

fn unavailable(reason: impl Into<String>) -> DdsError {
    DdsError::Unavailable {
        backend: "cyclone",
        reason: reason.into(),
    }
}

impl Api {
    fn load() -> Result<Api, DdsError> {
        let candidates: Vec<String> = match std::env::var("PERTURB_LIBDDSC") {
            Ok(p) => vec![p],
            Err(_) => vec![
                "libddsc.so.0debian".into(),
                "libddsc.so.0".into(),
                "libddsc.so".into(),
            ],
        };
        let mut errors = Vec::new();
        let mut lib = None;
        for c in &candidates {
            // SAFETY: loading libddsc runs its initialisers, which only set up Cyclone's globals.
            match unsafe { Library::new(c) } {
                Ok(l) => {
                    lib = Some(l);
                    break;
                }
                Err(e) => errors.push(format!("{c}: {e}")),
            }
        }
        let lib = lib.ok_or_else(|| {
            unavailable(format!(
                "cannot load Cyclone DDS 0.10 ({}); install it (Debian/Ubuntu: apt-get install cyclonedds-dev) or set PERTURB_LIBDDSC",
                errors.join("; ")
            ))
        })?;
        macro_rules! sym {
            ($name:literal) => {
                // SAFETY: the symbol's type is the C prototype of Cyclone DDS 0.10's dds.h.
                *unsafe { lib.get($name) }.map_err(|e| {
                    unavailable(format!(
                        "{} lacks {}: {e}",
                        candidates.join("|"),
                        String::from_utf8_lossy(&$name[..$name.len() - 1])
                    ))
                })?
            };
        }
        Ok(Api {
            create_domain: sym!(b"dds_create_domain\0"),
            create_participant: sym!(b"dds_create_participant\0"),
            create_topic: sym!(b"dds_create_topic\0"),
            create_writer: sym!(b"dds_create_writer\0"),
            create_reader: sym!(b"dds_create_reader\0"),
            create_readcondition: sym!(b"dds_create_readcondition\0"),
            create_waitset: sym!(b"dds_create_waitset\0"),
            waitset_attach: sym!(b"dds_waitset_attach\0"),
            waitset_wait: sym!(b"dds_waitset_wait\0"),
            write: sym!(b"dds_write\0"),
            take: sym!(b"dds_take\0"),
            return_loan: sym!(b"dds_return_loan\0"),
            delete: sym!(b"dds_delete\0"),
            create_qos: sym!(b"dds_create_qos\0"),
            delete_qos: sym!(b"dds_delete_qos\0"),
            qset_reliability: sym!(b"dds_qset_reliability\0"),
            qset_history: sym!(b"dds_qset_history\0"),
            qset_durability: sym!(b"dds_qset_durability\0"),
            get_publication_matched_status: sym!(b"dds_get_publication_matched_status\0"),
            get_offered_incompatible_qos_status: sym!(b"dds_get_offered_incompatible_qos_status\0"),
            strretcode: sym!(b"dds_strretcode\0"),
            _lib: lib,
        })
    }

    fn err(&self, rc: Ret) -> String {
        // SAFETY: dds_strretcode returns a static string for any code.
        let s = unsafe { (self.strretcode)(rc) };
        if s.is_null() {
            format!("error {rc}")
        } else {
            // SAFETY: non-null static C string.
            unsafe { CStr::from_ptr(s) }.to_string_lossy().into_owned()
        }
    }
}

/// The domain configuration used unless `CYCLONEDDS_URI` is set (or whenever interfaces are
/// given): 64 kB datagrams and 8 MB socket buffers, plus `<Interfaces>` when given.
fn domain_xml(nets: Option<&[Interface]>) -> String {
    let (interfaces, discovery) = nets
        .map(super::interfaces::cyclone_xml)
        .map(|f| (f.general, f.discovery))
        .unwrap_or_default();
    format!(
        "<CycloneDDS><Domain Id=\"any\"><General>{interfaces}<MaxMessageSize>65500B</MaxMessageSize></General>{discovery}<Internal><SocketReceiveBufferSize min=\"default\" max=\"8MB\"/><SocketSendBufferSize min=\"default\" max=\"8MB\"/></Internal></Domain></CycloneDDS>"
    )
}

/// libddsc, loaded once per process and never unloaded: Cyclone keeps thread-specific data
/// whose destructors run when any thread that called into it exits.
static API: std::sync::OnceLock<Result<Api, String>> = std::sync::OnceLock::new();

fn api() -> Result<&'static Api, DdsError> {
    API.get_or_init(|| Api::load().map_err(|e| e.to_string()))
        .as_ref()
        .map_err(|e| unavailable(e.clone()))
}

/// Ok if the Cyclone DDS library can be loaded here (else why not).
pub fn available() -> Result<(), DdsError> {
    api().map(|_| ())
}

struct Participant {
    api: &'static Api,
    participant: Entity,
}

impl Drop for Participant {
    fn drop(&mut self) {
        // SAFETY: deleting the participant deletes its children; nothing uses them afterwards
        // (readers and writers hold an Arc of this participant).
        unsafe { (self.api.delete)(self.participant) };
    }
}

/// Cyclone DDS: one participant.
pub struct CycloneBackend {
    p: Arc<Participant>,
}

impl CycloneBackend {
    /// Loads libddsc and creates a participant on `domain_id`, on the interfaces `nets` when
    /// given (which then take precedence over `CYCLONEDDS_URI`).
    pub fn new(domain_id: u16, nets: Option<&[Interface]>) -> Result<Self, DdsError> {
        let api = api()?;
        if nets.is_some() || std::env::var_os("CYCLONEDDS_URI").is_none() {
            let xml = CString::new(domain_xml(nets)).map_err(|_| DdsError::Setup {
                topic: "participant".into(),
                reason: "interface name with a NUL byte".into(),
            })?;
            // SAFETY: valid C string; a domain that exists already is reported, not fatal.
            let _ = unsafe { (api.create_domain)(domain_id as u32, xml.as_ptr()) };
        }
        // SAFETY: null QoS and listener are allowed.
        let participant = unsafe {
            (api.create_participant)(domain_id as u32, std::ptr::null(), std::ptr::null())
        };
        if participant < 0 {
            return Err(DdsError::Setup {
                topic: "participant".into(),
                reason: api.err(participant),
            });
        }
        Ok(CycloneBackend {
            p: Arc::new(Participant { api, participant }),
        })
    }

    fn qos(&self, spec: &TopicSpec) -> *mut Qos {
        let api = &self.p.api;
        // SAFETY: a fresh qos object, set with valid enum values; freed by the caller.
        unsafe {
            let q = (api.create_qos)();
            let (kind, block) = match spec.qos.reliability {
                super::Reliability::BestEffort => (0, 0),
                super::Reliability::Reliable => (1, 100_000_000),
            };
            (api.qset_reliability)(q, kind, block);
            (api.qset_history)(q, 0, spec.qos.depth.max(1) as i32);
            (api.qset_durability)(
                q,
                match spec.qos.durability {
                    super::Durability::Volatile => 0,
                    super::Durability::TransientLocal => 1,
                },
            );
            q
        }
    }

    fn topic(&self, spec: &TopicSpec, qos: *mut Qos) -> Result<Entity, DdsError> {
        let desc: &'static TopicDescriptor = match spec.ros_type {
            RosType::Image => &IMAGE_DESC,
            RosType::CompressedImage => &COMPRESSED_DESC,
            RosType::PointCloud2 => &CLOUD_DESC,
        };
        let name = CString::new(spec.dds_topic()).map_err(|e| DdsError::Setup {
            topic: spec.topic.clone(),
            reason: e.to_string(),
        })?;
        // SAFETY: the descriptor is 'static; name and qos are valid for the call.
        let t = unsafe {
            (self.p.api.create_topic)(
                self.p.participant,
                desc,
                name.as_ptr(),
                qos,
                std::ptr::null(),
            )
        };
        if t < 0 {
            return Err(DdsError::Setup {
                topic: spec.topic.clone(),
                reason: self.p.api.err(t),
            });
        }
        Ok(t)
    }
}

impl DdsBackend for CycloneBackend {
    fn name(&self) -> &'static str {
        "cyclone"
    }

    fn writer(&self, spec: &TopicSpec) -> Result<Box<dyn DdsWriter>, DdsError> {
        if spec.ros_type == RosType::CompressedImage {
            return Err(DdsError::Setup {
                topic: spec.topic.clone(),
                reason: "the bridge publishes raw images only (sensor_msgs/Image)".into(),
            });
        }
        let qos = self.qos(spec);
        let r = self.topic(spec, qos).and_then(|t| {
            // SAFETY: valid participant, topic and qos.
            let w =
                unsafe { (self.p.api.create_writer)(self.p.participant, t, qos, std::ptr::null()) };
            if w < 0 {
                Err(DdsError::Setup {
                    topic: spec.topic.clone(),
                    reason: self.p.api.err(w),
                })
            } else {
                Ok(w)
            }
        });
        // SAFETY: created above, not used after.
        unsafe { (self.p.api.delete_qos)(qos) };
        Ok(Box::new(CycloneWriter {
            p: self.p.clone(),
            writer: r?,
            topic: spec.topic.clone(),
        }))
    }

    fn reader(&self, spec: &TopicSpec) -> Result<Box<dyn DdsReader>, DdsError> {
        let qos = self.qos(spec);
        let api = &self.p.api;
        let setup = |rc: Entity| -> Result<Entity, DdsError> {
            if rc < 0 {
                Err(DdsError::Setup {
                    topic: spec.topic.clone(),
                    reason: api.err(rc),
                })
            } else {
                Ok(rc)
            }
        };
        let r = self.topic(spec, qos).and_then(|t| {
            // SAFETY: valid entities; 127 = DDS_ANY_STATE.
            unsafe {
                let reader = setup((api.create_reader)(
                    self.p.participant,
                    t,
                    qos,
                    std::ptr::null(),
                ))?;
                let cond = setup((api.create_readcondition)(reader, 127))?;
                let ws = setup((api.create_waitset)(self.p.participant))?;
                let rc = (api.waitset_attach)(ws, cond, 0);
                if rc < 0 {
                    return Err(DdsError::Setup {
                        topic: spec.topic.clone(),
                        reason: api.err(rc),
                    });
                }
                Ok((reader, ws))
            }
        });
        // SAFETY: created above, not used after.
        unsafe { (api.delete_qos)(qos) };
        let (reader, waitset) = r?;
        Ok(Box::new(CycloneReader {
            p: self.p.clone(),
            reader,
            waitset,
            spec: spec.clone(),
        }))
    }
}

struct CycloneWriter {
    p: Arc<Participant>,
    writer: Entity,
    topic: String,
}

// SAFETY: Cyclone entities are handles usable from any thread.
unsafe impl Send for CycloneWriter {}

fn header(h: &Header<'_>, frame_id: &CString) -> CHeader {
    CHeader {
        stamp: Time {
            sec: h.stamp_sec,
            nanosec: h.stamp_nanosec,
        },
        frame_id: frame_id.as_ptr() as *mut c_char,
    }
}

fn seq(data: &[u8]) -> SeqU8 {
    SeqU8 {
        maximum: data.len() as u32,
        length: data.len() as u32,
        buffer: data.as_ptr() as *mut u8,
        release: false,
    }
}

fn cstring(s: &str, topic: &str, field: &str) -> Result<CString, DdsError> {
    CString::new(s).map_err(|_| DdsError::Write {
        topic: topic.to_string(),
        reason: format!("`{field}` contains a NUL byte"),
    })
}

impl DdsWriter for CycloneWriter {
    fn write(&mut self, msg: &Payload<'_>) -> Result<(), DdsError> {
        let api = &self.p.api;
        let h = msg.header();
        let frame_id = cstring(h.frame_id, &self.topic, "header.frame_id")?;
        let rc = match msg {
            Payload::Image(m) => {
                let encoding = cstring(m.encoding, &self.topic, "encoding")?;
                let c = CImage {
                    header: header(h, &frame_id),
                    height: m.height,
                    width: m.width,
                    encoding: encoding.as_ptr() as *mut c_char,
                    is_bigendian: m.is_bigendian,
                    step: m.step,
                    data: seq(m.data),
                };
                // SAFETY: the struct borrows live data; Cyclone only reads it during the call.
                unsafe { (api.write)(self.writer, &c as *const CImage as *const c_void) }
            }
            Payload::Cloud(m) => {
                let names = m
                    .fields
                    .iter()
                    .map(|f| cstring(&f.name, &self.topic, "fields[].name"))
                    .collect::<Result<Vec<_>, _>>()?;
                let mut fields: Vec<CPointField> = m
                    .fields
                    .iter()
                    .zip(&names)
                    .map(|(f, n)| CPointField {
                        name: n.as_ptr() as *mut c_char,
                        offset: f.offset,
                        datatype: f.datatype.code(),
                        count: f.count,
                    })
                    .collect();
                let c = CCloud {
                    header: header(h, &frame_id),
                    height: m.height,
                    width: m.width,
                    fields: SeqField {
                        maximum: fields.len() as u32,
                        length: fields.len() as u32,
                        buffer: fields.as_mut_ptr(),
                        release: false,
                    },
                    is_bigendian: m.is_bigendian,
                    point_step: m.point_step,
                    row_step: m.row_step,
                    data: seq(m.data),
                    is_dense: m.is_dense,
                };
                // SAFETY: as above.
                unsafe { (api.write)(self.writer, &c as *const CCloud as *const c_void) }
            }
        };
        if rc < 0 {
            return Err(DdsError::Write {
                topic: self.topic.clone(),
                reason: api.err(rc),
            });
        }
        Ok(())
    }

    fn matched(&self) -> Option<usize> {
        let mut st = PublicationMatched::default();
        // SAFETY: valid writer and out-pointer.
        let rc = unsafe { (self.p.api.get_publication_matched_status)(self.writer, &mut st) };
        (rc >= 0).then_some(st.current_count as usize)
    }

    fn incompatible_readers(&mut self) -> Option<super::IncompatibleReaders> {
        let mut st = OfferedIncompatibleQos::default();
        // SAFETY: valid writer and out-pointer.
        let rc = unsafe { (self.p.api.get_offered_incompatible_qos_status)(self.writer, &mut st) };
        (rc >= 0 && st.total_count > 0).then(|| super::IncompatibleReaders {
            total: st.total_count.into(),
            policy: super::policy_name(st.last_policy_id),
        })
    }
}

struct CycloneReader {
    p: Arc<Participant>,
    reader: Entity,
    waitset: Entity,
    spec: TopicSpec,
}

// SAFETY: Cyclone entities are handles usable from any thread.
unsafe impl Send for CycloneReader {}

/// # Safety
/// `p` must be null or a NUL-terminated string that outlives `'a`.
unsafe fn c_str<'a>(p: *const c_char, field: &str) -> Result<&'a str, perturb_core::Error> {
    if p.is_null() {
        return Ok("");
    }
    // SAFETY: per the function contract.
    unsafe { CStr::from_ptr(p) }.to_str().map_err(|_| {
        perturb_core::Error::malformed("DDS sample", format!("`{field}` is not UTF-8"))
    })
}

/// # Safety
/// `s` must describe a live buffer of `length` bytes that outlives `'a`.
unsafe fn bytes<'a>(s: &SeqU8) -> &'a [u8] {
    if s.buffer.is_null() || s.length == 0 {
        &[]
    } else {
        // SAFETY: per the function contract.
        unsafe { std::slice::from_raw_parts(s.buffer, s.length as usize) }
    }
}

/// Views a loaned sample as a message.
///
/// # Safety
/// `sample` must point at a live sample of the topic's type.
unsafe fn view<'a>(
    ty: RosType,
    sample: *const c_void,
) -> Result<Received<'a>, perturb_core::Error> {
    // SAFETY: (the whole body) the caller guarantees `sample` is a valid loaned sample of `ty`,
    // whose strings and sequences Cyclone keeps alive until the loan is returned.
    unsafe {
        match ty {
            RosType::Image => {
                let c = &*(sample as *const CImage);
                Ok(Received::Image(ImageMsg {
                    header: Header {
                        stamp_sec: c.header.stamp.sec,
                        stamp_nanosec: c.header.stamp.nanosec,
                        frame_id: c_str(c.header.frame_id, "header.frame_id")?,
                    },
                    height: c.height,
                    width: c.width,
                    encoding: c_str(c.encoding, "encoding")?,
                    is_bigendian: c.is_bigendian,
                    step: c.step,
                    data: bytes(&c.data),
                }))
            }
            RosType::CompressedImage => {
                let c = &*(sample as *const CCompressed);
                Ok(Received::Compressed(CompressedImageMsg {
                    header: Header {
                        stamp_sec: c.header.stamp.sec,
                        stamp_nanosec: c.header.stamp.nanosec,
                        frame_id: c_str(c.header.frame_id, "header.frame_id")?,
                    },
                    format: c_str(c.format, "format")?,
                    data: bytes(&c.data),
                }))
            }
            RosType::PointCloud2 => {
                let c = &*(sample as *const CCloud);
                let raw = if c.fields.buffer.is_null() {
                    &[][..]
                } else {
                    std::slice::from_raw_parts(c.fields.buffer, c.fields.length as usize)
                };
                let mut fields = Vec::with_capacity(raw.len());
                for f in raw {
                    let name = c_str(f.name, "fields[].name")?;
                    let datatype = Datatype::from_code(f.datatype).ok_or_else(|| {
                        perturb_core::Error::malformed(
                            "sensor_msgs/PointCloud2",
                            format!("field `{name}` has unknown datatype {}", f.datatype),
                        )
                    })?;
                    fields.push(PointField {
                        name: name.to_string(),
                        offset: f.offset,
                        datatype,
                        count: f.count,
                    });
                }
                Ok(Received::Cloud(PointCloud2Msg {
                    header: Header {
                        stamp_sec: c.header.stamp.sec,
                        stamp_nanosec: c.header.stamp.nanosec,
                        frame_id: c_str(c.header.frame_id, "header.frame_id")?,
                    },
                    height: c.height,
                    width: c.width,
                    fields,
                    is_bigendian: c.is_bigendian,
                    point_step: c.point_step,
                    row_step: c.row_step,
                    data: bytes(&c.data),
                    is_dense: c.is_dense,
                }))
            }
        }
    }
}

impl CycloneReader {
    fn drain(
        &mut self,
        f: &mut dyn FnMut(Result<Received<'_>, perturb_core::Error>),
    ) -> Result<usize, DdsError> {
        let api = &self.p.api;
        let mut total = 0;
        loop {
            const N: usize = 8;
            let mut buf = [std::ptr::null_mut::<c_void>(); N];
            let mut infos: [SampleInfo; N] = Default::default();
            // SAFETY: buf[0] == NULL asks Cyclone to loan the samples; returned below.
            let n = unsafe {
                (api.take)(
                    self.reader,
                    buf.as_mut_ptr(),
                    infos.as_mut_ptr(),
                    N,
                    N as u32,
                )
            };
            if n < 0 {
                return Err(DdsError::Read {
                    topic: self.spec.topic.clone(),
                    reason: api.err(n),
                });
            }
            if n == 0 {
                return Ok(total);
            }
            for i in 0..n as usize {
                if infos[i].valid_data {
                    total += 1;
                    // SAFETY: a valid loaned sample of the reader's type.
                    f(unsafe { view(self.spec.ros_type, buf[i]) });
                }
            }
            // SAFETY: returning the loan taken above.
            unsafe { (api.return_loan)(self.reader, buf.as_mut_ptr(), n) };
        }
    }
}

impl DdsReader for CycloneReader {
    fn take(
        &mut self,
        timeout: Duration,
        f: &mut dyn FnMut(Result<Received<'_>, perturb_core::Error>),
    ) -> Result<usize, DdsError> {
        let n = self.drain(f)?;
        if n > 0 {
            return Ok(n);
        }
        let mut xs = [0isize; 1];
        // SAFETY: valid waitset and buffer.
        let rc = unsafe {
            (self.p.api.waitset_wait)(
                self.waitset,
                xs.as_mut_ptr(),
                1,
                timeout.as_nanos().min(i64::MAX as u128) as i64,
            )
        };
        if rc < 0 {
            return Err(DdsError::Read {
                topic: self.spec.topic.clone(),
                reason: self.p.api.err(rc),
            });
        }
        self.drain(f)
    }
}
