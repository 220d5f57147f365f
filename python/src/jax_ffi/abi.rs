//! `#[repr(C)]` mirrors of the parts of XLA's FFI C API (`xla/ffi/api/c_api.h`, API version 0.3
//! as shipped in jaxlib 0.10.2) that the handler reads or writes, and the few unsafe readers of a
//! call frame. Nothing here knows hybc; `handler.rs` turns a call frame into slices through these.
//!
//! The header promises that old API versions stay supported for at least 12 months and that
//! structs only grow at their end (`struct_size` tells how much of a struct the other side
//! knows), so every struct read here is first checked to be at least as large as ours. The
//! layout assertions below pin each struct's size to the header's `XLA_FFI_STRUCT_SIZE` value
//! (the offset of the last field plus its size) on 64-bit targets.

use std::ffi::{c_char, c_int, c_void};
use std::mem::{offset_of, size_of};
use std::ptr::NonNull;

/// `XLA_FFI_API_MAJOR` / `XLA_FFI_API_MINOR` of the header these mirrors follow: what the
/// handler reports in the metadata stage.
pub const API_MAJOR: c_int = 0;
pub const API_MINOR: c_int = 3;

/// `XLA_FFI_Extension_Metadata`.
pub const EXTENSION_METADATA: c_int = 1;
/// `XLA_FFI_ExecutionStage_EXECUTE`.
pub const STAGE_EXECUTE: c_int = 3;
/// `XLA_FFI_ArgType_BUFFER` and `XLA_FFI_RetType_BUFFER`.
pub const BUFFER: c_int = 1;
/// `XLA_FFI_AttrType_SCALAR`.
pub const ATTR_SCALAR: c_int = 3;

/// `XLA_FFI_DataType` values the handler accepts or names.
pub mod dtype {
    use std::ffi::c_int;
    pub const S32: c_int = 4;
    pub const S64: c_int = 5;
    pub const U64: c_int = 9;
    pub const F32: c_int = 11;
    pub const F64: c_int = 12;

    /// The name jax.numpy uses, for messages.
    pub fn name(d: c_int) -> String {
        match d {
            1 => "bool".into(),
            2 => "int8".into(),
            3 => "int16".into(),
            S32 => "int32".into(),
            S64 => "int64".into(),
            6 => "uint8".into(),
            7 => "uint16".into(),
            8 => "uint32".into(),
            U64 => "uint64".into(),
            10 => "float16".into(),
            F32 => "float32".into(),
            F64 => "float64".into(),
            16 => "bfloat16".into(),
            other => format!("XLA data type {other}"),
        }
    }
}

/// `XLA_FFI_Error_Code_INVALID_ARGUMENT` and `..._INTERNAL`.
pub const ERROR_INVALID_ARGUMENT: c_int = 3;
pub const ERROR_INTERNAL: c_int = 13;

#[repr(C)]
pub struct ExtensionBase {
    pub struct_size: usize,
    pub kind: c_int,
    pub next: *mut ExtensionBase,
}

#[repr(C)]
pub struct ApiVersion {
    pub struct_size: usize,
    pub extension_start: *mut ExtensionBase,
    pub major_version: c_int,
    pub minor_version: c_int,
}

/// Opaque `XLA_FFI_Error`: created by the API, owned by XLA once returned.
#[repr(C)]
pub struct XlaError {
    _private: [u8; 0],
}

#[repr(C)]
pub struct ErrorCreateArgs {
    pub struct_size: usize,
    pub extension_start: *mut ExtensionBase,
    pub message: *const c_char,
    pub errc: c_int,
}

pub type ErrorCreate = unsafe extern "C" fn(*mut ErrorCreateArgs) -> *mut XlaError;

/// The head of `XLA_FFI_Api`, up to the one function the handler calls (`XLA_FFI_Error_Create`,
/// the first function pointer). The struct goes on in XLA's memory; it is only read through a
/// pointer XLA gives, never built here.
#[repr(C)]
pub struct ApiHead {
    pub struct_size: usize,
    pub extension_start: *mut ExtensionBase,
    pub api_version: ApiVersion,
    pub internal_api: *const c_void,
    pub error_create: Option<ErrorCreate>,
}

#[repr(C)]
pub struct Buffer {
    pub struct_size: usize,
    pub extension_start: *mut ExtensionBase,
    pub dtype: c_int,
    pub data: *mut c_void,
    pub rank: i64,
    pub dims: *mut i64,
}

#[repr(C)]
pub struct Args {
    pub struct_size: usize,
    pub extension_start: *mut ExtensionBase,
    pub size: i64,
    pub types: *mut c_int,
    pub args: *mut *mut c_void,
}

#[repr(C)]
pub struct Rets {
    pub struct_size: usize,
    pub extension_start: *mut ExtensionBase,
    pub size: i64,
    pub types: *mut c_int,
    pub rets: *mut *mut c_void,
}

#[repr(C)]
pub struct ByteSpan {
    pub ptr: *const c_char,
    pub len: usize,
}

#[repr(C)]
pub struct Scalar {
    pub dtype: c_int,
    pub value: *mut c_void,
}

/// Attributes, sorted by name.
#[repr(C)]
pub struct Attrs {
    pub struct_size: usize,
    pub extension_start: *mut ExtensionBase,
    pub size: i64,
    pub types: *mut c_int,
    pub names: *mut *mut ByteSpan,
    pub attrs: *mut *mut c_void,
}

#[repr(C)]
pub struct CallFrame {
    pub struct_size: usize,
    pub extension_start: *mut ExtensionBase,
    pub api: *const ApiHead,
    pub ctx: *mut c_void,
    pub stage: c_int,
    pub args: Args,
    pub rets: Rets,
    pub attrs: Attrs,
    pub future: *mut c_void,
}

#[repr(C)]
pub struct Metadata {
    pub struct_size: usize,
    pub api_version: ApiVersion,
    pub traits: u32,
    pub state_type_id: i64,
}

#[repr(C)]
pub struct MetadataExtension {
    pub extension_base: ExtensionBase,
    pub metadata: *mut Metadata,
}

/// `XLA_FFI_STRUCT_SIZE(T, last)`: the bytes of `T` up to and including its last field.
macro_rules! struct_size {
    ($t:ty, $last:ident, $last_ty:ty) => {
        offset_of!($t, $last) + size_of::<$last_ty>()
    };
}

pub const CALL_FRAME_SIZE: usize = struct_size!(CallFrame, attrs, Attrs);
pub const BUFFER_SIZE: usize = struct_size!(Buffer, dims, *mut i64);
pub const ARGS_SIZE: usize = struct_size!(Args, args, *mut *mut c_void);
pub const RETS_SIZE: usize = struct_size!(Rets, rets, *mut *mut c_void);
pub const ATTRS_SIZE: usize = struct_size!(Attrs, attrs, *mut *mut c_void);
pub const API_VERSION_SIZE: usize = struct_size!(ApiVersion, minor_version, c_int);
pub const ERROR_CREATE_ARGS_SIZE: usize = struct_size!(ErrorCreateArgs, errc, c_int);
pub const METADATA_SIZE: usize = struct_size!(Metadata, traits, u32);
pub const METADATA_EXTENSION_SIZE: usize = struct_size!(MetadataExtension, metadata, *mut Metadata);
pub const API_HEAD_SIZE: usize = struct_size!(ApiHead, error_create, Option<ErrorCreate>);

// The header's sizes on a 64-bit target (computed by hand from c_api.h 0.3): a mirror that
// drifted from the header fails to compile rather than reading the wrong bytes.
#[cfg(target_pointer_width = "64")]
const _: () = {
    assert!(CALL_FRAME_SIZE == 168);
    assert!(offset_of!(CallFrame, stage) == 32);
    assert!(offset_of!(CallFrame, args) == 40);
    assert!(BUFFER_SIZE == 48);
    assert!(ARGS_SIZE == 40 && RETS_SIZE == 40 && ATTRS_SIZE == 48);
    assert!(API_VERSION_SIZE == 24);
    assert!(ERROR_CREATE_ARGS_SIZE == 28);
    assert!(METADATA_SIZE == 36);
    assert!(offset_of!(Metadata, state_type_id) == 40);
    assert!(METADATA_EXTENSION_SIZE == 32);
    assert!(offset_of!(ApiHead, error_create) == 48);
};

/// A non-null pointer for a slice of `len` elements starting at `data`: XLA may hand a null or
/// dangling pointer for an empty buffer, which `slice::from_raw_parts` must not see.
pub fn slice_ptr<T>(data: *mut c_void, len: usize) -> Option<NonNull<T>> {
    if len == 0 {
        return Some(NonNull::dangling());
    }
    let p = NonNull::new(data.cast::<T>())?;
    p.as_ptr().is_aligned().then_some(p)
}
