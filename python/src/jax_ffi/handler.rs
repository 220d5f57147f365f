//! The XLA FFI handler: one `extern "C"` function serving every `hybc.jax.function`.
//!
//! XLA calls it once with a metadata extension (to learn the API version it was built against)
//! and then in the execute stage with one input buffer and four or six result buffers (see
//! `hybc/jax.py`):
//!
//! | buffer | dtype | shape (after the batch dimensions `B...`) |
//! | --- | --- | --- |
//! | in: `p` | f64 | `(m,)` inputs |
//! | out: `values` | f64 | `(n,)` |
//! | out: `dvalues` (Jacobian calls only) | f64 | `(n, m)` |
//! | out: `times` | f64 | `(K,)` |
//! | out: `dtimes` (Jacobian calls only) | f64 | `(K, m)` |
//! | out: `n_events`, `status` | s32 | `()` |
//!
//! or, for reverse mode's pull-back (`Function::pull_back_batch`), three input buffers and one
//! result buffer:
//!
//! | buffer | dtype | shape (after `B...`) |
//! | --- | --- | --- |
//! | in: `p` | f64 | `(m,)` inputs |
//! | in: `ct_values` | f64 | `(n,)` the values' cotangent |
//! | in: `ct_times` | f64 | `(K,)` the event times' cotangent |
//! | out: `pbar` | f64 | `(m,)` the inputs' cotangent |
//!
//! and one attribute, `handle` (s64), naming the function in the registry. Leading dimensions
//! `B...` (what `vmap_method="broadcast_all"` adds) are a batch run in one call. A malformed
//! call (wrong dtype, shape or handle) is an INVALID_ARGUMENT error naming what is wrong; a
//! panic is caught here and becomes an INTERNAL error, never an unwind into XLA.

use std::ffi::{c_int, c_void, CString};
use std::panic::{catch_unwind, AssertUnwindSafe};

use super::abi::{self, dtype, CallFrame, XlaError};
use super::function::Outputs;
use super::registry;

/// The handler XLA calls (registered from Python through `jax.ffi.pycapsule`).
///
/// # Safety
/// `frame` must be a call frame XLA built for this call, valid for its duration.
pub unsafe extern "C" fn hybc_jax_handler(frame: *mut CallFrame) -> *mut XlaError {
    if frame.is_null() {
        return std::ptr::null_mut();
    }
    // SAFETY: XLA passes a valid call frame for the duration of the call; only its head (present in
    // every API version) is read before `struct_size` is checked.
    let api = unsafe { (*frame).api };
    let outcome = catch_unwind(AssertUnwindSafe(|| {
        // SAFETY: as above; `handle` checks `struct_size` before reading past the head.
        unsafe { handle(frame) }
    }));
    let failure = match outcome {
        Ok(Ok(())) => return std::ptr::null_mut(),
        Ok(Err(failure)) => failure,
        Err(panic) => {
            Failure::internal(format!("hybc: panic in the JAX handler: {}", panic_message(&*panic)))
        }
    };
    // SAFETY: `api` came from the frame; `make_error` checks it.
    unsafe { make_error(api, &failure) }
}

/// Why a call failed: an XLA error code and a message.
struct Failure {
    code: c_int,
    message: String,
}

impl Failure {
    fn invalid(message: impl Into<String>) -> Failure {
        Failure { code: abi::ERROR_INVALID_ARGUMENT, message: message.into() }
    }
    fn internal(message: impl Into<String>) -> Failure {
        Failure { code: abi::ERROR_INTERNAL, message: message.into() }
    }
}

fn panic_message(panic: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = panic.downcast_ref::<&str>() {
        s.to_string()
    } else if let Some(s) = panic.downcast_ref::<String>() {
        s.clone()
    } else {
        "(no message)".to_string()
    }
}

/// An XLA error carrying `failure`, created through the API's `XLA_FFI_Error_Create`.
///
/// # Safety
/// `api` must be null or the API pointer of a live call frame.
unsafe fn make_error(api: *const abi::ApiHead, failure: &Failure) -> *mut XlaError {
    // SAFETY: a non-null `api` points to XLA's API struct, whose head is read only after its
    // `struct_size` shows it holds `error_create`.
    let create = unsafe { api.as_ref() }
        .filter(|api| api.struct_size >= abi::API_HEAD_SIZE)
        .and_then(|api| api.error_create);
    let Some(create) = create else {
        // Without the API there is no way to report; XLA would then read success. This only
        // happens with a frame XLA did not build, which `hybc/jax.py` never produces.
        return std::ptr::null_mut();
    };
    let message = CString::new(failure.message.replace('\0', " ")).unwrap_or_default();
    let mut args = abi::ErrorCreateArgs {
        struct_size: abi::ERROR_CREATE_ARGS_SIZE,
        extension_start: std::ptr::null_mut(),
        message: message.as_ptr(),
        errc: failure.code,
    };
    // SAFETY: `args` is a valid `XLA_FFI_Error_Create_Args`; XLA copies the message before
    // returning (the C++ helpers in `ffi/api/api.h` pass a temporary string the same way).
    unsafe { create(&mut args) }
}

/// Answers the metadata query or runs the call.
///
/// # Safety
/// As [`hybc_jax_handler`].
unsafe fn handle(frame: *mut CallFrame) -> Result<(), Failure> {
    // SAFETY: `struct_size` is the frame's first field, present in every version.
    let frame_size = unsafe { (*frame).struct_size };
    if frame_size < abi::CALL_FRAME_SIZE {
        return Err(Failure::invalid(format!(
            "hybc: XLA's call frame has {frame_size} bytes, hybc reads {} (XLA FFI API 0.{} or newer needed)",
            abi::CALL_FRAME_SIZE,
            abi::API_MINOR
        )));
    }
    // SAFETY: the frame holds every field of `CallFrame` (checked just above).
    let frame = unsafe { &*frame };
    if !frame.extension_start.is_null() {
        // SAFETY: a non-null extension chain starts with an `XLA_FFI_Extension_Base`.
        let ext = unsafe { &*frame.extension_start };
        if ext.kind == abi::EXTENSION_METADATA {
            // SAFETY: an extension of kind metadata is an `XLA_FFI_Metadata_Extension`.
            return unsafe { fill_metadata(frame.extension_start.cast()) };
        }
    }
    if frame.stage != abi::STAGE_EXECUTE {
        // Registered with an execute handler only; nothing to do in other stages.
        return Ok(());
    }
    // SAFETY: in the execute stage the frame's arguments, results and attributes are live.
    unsafe { execute(frame) }
}

/// Reports the API version these mirrors follow, no traits and no state.
///
/// # Safety
/// `ext` must point to a metadata extension XLA built.
unsafe fn fill_metadata(ext: *mut abi::MetadataExtension) -> Result<(), Failure> {
    // SAFETY: `ext` is a live metadata extension; its sizes are checked before its metadata is
    // written, and `XLA_FFI_Metadata` is written field by field as the header's own handler
    // (`PopulateMetadata` in ffi/api/api.h) does.
    unsafe {
        if (*ext).extension_base.struct_size < abi::METADATA_EXTENSION_SIZE || (*ext).metadata.is_null() {
            return Err(Failure::invalid("hybc: XLA's metadata extension is smaller than API 0.3's"));
        }
        let metadata = (*ext).metadata;
        if (*metadata).struct_size < abi::METADATA_SIZE {
            return Err(Failure::invalid("hybc: XLA's handler metadata is smaller than API 0.3's"));
        }
        (*metadata).api_version = abi::ApiVersion {
            struct_size: abi::API_VERSION_SIZE,
            extension_start: std::ptr::null_mut(),
            major_version: abi::API_MAJOR,
            minor_version: abi::API_MINOR,
        };
        (*metadata).traits = 0;
        (*metadata).state_type_id = 0;
    }
    Ok(())
}

/// A buffer's element type, dimensions and data pointer, read from XLA's struct.
struct BufferView {
    dtype: c_int,
    dims: Vec<usize>,
    data: *mut c_void,
}

impl BufferView {
    fn len(&self) -> usize {
        self.dims.iter().product()
    }
}

/// Reads the `i`-th buffer of an argument or result list.
///
/// # Safety
/// `types` and `ptrs` must be XLA's arrays of `size` entries.
unsafe fn read_buffer(
    what: &str,
    i: usize,
    size: i64,
    types: *const c_int,
    ptrs: *const *mut c_void,
) -> Result<BufferView, Failure> {
    if i as i64 >= size || types.is_null() || ptrs.is_null() {
        return Err(Failure::invalid(format!("hybc: {what} {i} missing")));
    }
    // SAFETY: `i < size`, and both arrays hold `size` entries.
    let (kind, ptr) = unsafe { (*types.add(i), *ptrs.add(i)) };
    if kind != abi::BUFFER || ptr.is_null() {
        return Err(Failure::invalid(format!("hybc: {what} {i} is not a buffer")));
    }
    // SAFETY: a buffer entry points to an `XLA_FFI_Buffer`; its size is checked before the fields
    // past `struct_size` are read, and `dims` holds `rank` entries.
    unsafe {
        let buffer = &*ptr.cast::<abi::Buffer>();
        if buffer.struct_size < abi::BUFFER_SIZE {
            return Err(Failure::invalid(format!("hybc: {what} {i}: XLA's buffer struct is too small")));
        }
        let rank = usize::try_from(buffer.rank).map_err(|_| Failure::invalid("hybc: negative rank"))?;
        let dims = if rank == 0 {
            Vec::new()
        } else if buffer.dims.is_null() {
            return Err(Failure::invalid(format!("hybc: {what} {i} has no dimensions")));
        } else {
            std::slice::from_raw_parts(buffer.dims, rank)
                .iter()
                .map(|&d| usize::try_from(d).map_err(|_| Failure::invalid("hybc: negative dimension")))
                .collect::<Result<Vec<_>, _>>()?
        };
        Ok(BufferView { dtype: buffer.dtype, dims, data: buffer.data })
    }
}

/// The `handle` attribute.
///
/// # Safety
/// `attrs` must be XLA's attribute list of a live call frame.
unsafe fn read_handle(attrs: &abi::Attrs) -> Result<u64, Failure> {
    if attrs.struct_size < abi::ATTRS_SIZE {
        return Err(Failure::invalid("hybc: XLA's attribute list is too small"));
    }
    let size = usize::try_from(attrs.size).unwrap_or(0);
    if size > 0 && (attrs.names.is_null() || attrs.types.is_null() || attrs.attrs.is_null()) {
        return Err(Failure::invalid("hybc: XLA's attribute list has null arrays"));
    }
    for i in 0..size {
        // SAFETY: the three arrays hold `size` entries (checked non-null); a name is a byte span
        // of `len` bytes, a scalar attribute points to an `XLA_FFI_Scalar` whose value has its
        // dtype's size. Null pointers are refused before they are read.
        unsafe {
            let name = *attrs.names.add(i);
            if name.is_null() || (*name).ptr.is_null() {
                continue;
            }
            let name = std::slice::from_raw_parts((*name).ptr.cast::<u8>(), (*name).len);
            if name != b"handle" {
                continue;
            }
            let attr = *attrs.attrs.add(i);
            if *attrs.types.add(i) != abi::ATTR_SCALAR || attr.is_null() {
                return Err(Failure::invalid("hybc: attribute `handle` is not a scalar"));
            }
            let scalar = &*attr.cast::<abi::Scalar>();
            if scalar.value.is_null() {
                return Err(Failure::invalid("hybc: attribute `handle` has no value"));
            }
            return match scalar.dtype {
                dtype::S64 => u64::try_from(*scalar.value.cast::<i64>())
                    .map_err(|_| Failure::invalid("hybc: negative function handle")),
                dtype::U64 => Ok(*scalar.value.cast::<u64>()),
                other => Err(Failure::invalid(format!(
                    "hybc: attribute `handle` is {}, not int64",
                    dtype::name(other)
                ))),
            };
        }
    }
    Err(Failure::invalid("hybc: the call has no `handle` attribute (call it through hybc.jax.function)"))
}

/// A result buffer as a mutable slice of `T` after checking its dtype and pointer.
///
/// # Safety
/// `view` must describe a live XLA result buffer that nothing else accesses during the call.
unsafe fn as_slice<'a, T>(view: &BufferView, want_dtype: c_int, what: &str) -> Result<&'a mut [T], Failure> {
    let (ptr, len) = checked_ptr::<T>(view, want_dtype, what)?;
    // SAFETY: XLA's result buffer holds `len` elements of `want_dtype` (= `T`), checked non-null
    // and aligned; XLA does not touch it while the handler runs, and no two buffers of one call
    // overlap (`hybc/jax.py` aliases none).
    Ok(unsafe { std::slice::from_raw_parts_mut(ptr.as_ptr(), len) })
}

/// An input buffer as a slice of `T` after checking its dtype and pointer.
///
/// # Safety
/// `view` must describe a live XLA input buffer.
unsafe fn as_input<'a, T>(view: &BufferView, want_dtype: c_int, what: &str) -> Result<&'a [T], Failure> {
    let (ptr, len) = checked_ptr::<T>(view, want_dtype, what)?;
    // SAFETY: as `as_slice`; the input is only read.
    Ok(unsafe { std::slice::from_raw_parts(ptr.as_ptr(), len) })
}

fn checked_ptr<T>(
    view: &BufferView,
    want_dtype: c_int,
    what: &str,
) -> Result<(std::ptr::NonNull<T>, usize), Failure> {
    if view.dtype != want_dtype {
        return Err(Failure::invalid(format!(
            "hybc: {what} is {}, expected {}",
            dtype::name(view.dtype),
            dtype::name(want_dtype)
        )));
    }
    let len = view.len();
    let ptr = abi::slice_ptr::<T>(view.data, len)
        .ok_or_else(|| Failure::invalid(format!("hybc: {what}: null or misaligned data")))?;
    Ok((ptr, len))
}

/// Checks that `view` has shape `batch ++ tail`.
fn check_shape(view: &BufferView, batch: &[usize], tail: &[usize], what: &str) -> Result<(), Failure> {
    let expected: Vec<usize> = batch.iter().chain(tail).copied().collect();
    if view.dims == expected {
        Ok(())
    } else {
        Err(Failure::invalid(format!("hybc: {what} has shape {:?}, expected {:?}", view.dims, expected)))
    }
}

/// Decodes the buffers and runs the batch.
///
/// # Safety
/// `frame` must be a live call frame in the execute stage.
unsafe fn execute(frame: &CallFrame) -> Result<(), Failure> {
    if frame.args.struct_size < abi::ARGS_SIZE || frame.rets.struct_size < abi::RETS_SIZE {
        return Err(Failure::invalid("hybc: XLA's argument or result list is too small"));
    }
    // SAFETY: the attribute list of a live frame.
    let handle = unsafe { read_handle(&frame.attrs)? };
    let function = registry::get(handle)
        .ok_or_else(|| Failure::invalid(format!("hybc: no function with handle {handle} in this process")))?;
    let (m, n, k) = (function.n_inputs(), function.n_values(), function.n_event_slots());

    let (args, rets) = (&frame.args, &frame.rets);
    /// What a call asks for, by its buffer counts.
    enum Call {
        Values,
        WithJacobians,
        PullBack,
    }
    let call = match (args.size, rets.size) {
        (1, 4) => Call::Values,
        (1, 6) => Call::WithJacobians,
        (3, 1) => Call::PullBack,
        (1, other) => {
            return Err(Failure::invalid(format!("hybc: expected 4 or 6 result buffers, got {other}")))
        }
        (inputs, results) => {
            return Err(Failure::invalid(format!(
                "hybc: expected 1 input buffer (values) or 3 (a pull-back), got {inputs} inputs and \
                 {results} results"
            )))
        }
    };
    // SAFETY: `args`/`rets` are the frame's live lists of `size` entries.
    let arg = |i| unsafe { read_buffer("input", i, args.size, args.types, args.args) };
    let ret = |i| unsafe { read_buffer("result", i, rets.size, rets.types, rets.rets) };

    let p = arg(0)?;
    if p.dtype == dtype::F32 {
        return Err(Failure::invalid(
            "hybc: the parameters are float32; hybc.jax computes in float64: call \
             jax.config.update(\"jax_enable_x64\", True) before building arrays",
        ));
    }
    let batch_dims = match p.dims.split_last() {
        Some((&last, batch)) if last == m => batch.to_vec(),
        _ => {
            return Err(Failure::invalid(format!(
                "hybc: the parameters have shape {:?}; {} takes {m} inputs ({}), as the last dimension",
                p.dims,
                function.model_name,
                function.input_names().join(", ")
            )))
        }
    };
    let batch: usize = batch_dims.iter().product();

    let views: Vec<BufferView> = (0..rets.size as usize).map(ret).collect::<Result<_, _>>()?;
    let with_jacobians = match call {
        Call::Values => false,
        Call::WithJacobians => true,
        Call::PullBack => {
            let (ct_values, ct_times, pbar) = (arg(1)?, arg(2)?, &views[0]);
            check_shape(&ct_values, &batch_dims, &[n], "the values' cotangent")?;
            check_shape(&ct_times, &batch_dims, &[k], "the event times' cotangent")?;
            check_shape(pbar, &batch_dims, &[m], "the parameters' cotangent")?;
            // SAFETY: live, distinct XLA buffers of this call, checked for dtype and shape; the
            // inputs are only read.
            let (p, ct_values, ct_times, pbar) = unsafe {
                (
                    as_input::<f64>(&p, dtype::F64, "the parameters")?,
                    as_input::<f64>(&ct_values, dtype::F64, "the values' cotangent")?,
                    as_input::<f64>(&ct_times, dtype::F64, "the event times' cotangent")?,
                    as_slice::<f64>(pbar, dtype::F64, "the parameters' cotangent")?,
                )
            };
            function.pull_back_batch(p, batch, ct_values, ct_times, pbar);
            return Ok(());
        }
    };
    let (values, dvalues, times, dtimes, n_events, status) = if with_jacobians {
        (&views[0], Some(&views[1]), &views[2], Some(&views[3]), &views[4], &views[5])
    } else {
        (&views[0], None, &views[1], None, &views[2], &views[3])
    };
    check_shape(values, &batch_dims, &[n], "values")?;
    check_shape(times, &batch_dims, &[k], "event times")?;
    check_shape(n_events, &batch_dims, &[], "n_events")?;
    check_shape(status, &batch_dims, &[], "status")?;
    if let (Some(dv), Some(dt)) = (dvalues, dtimes) {
        check_shape(dv, &batch_dims, &[n, m], "value Jacobian")?;
        check_shape(dt, &batch_dims, &[k, m], "event time Jacobian")?;
    }

    // SAFETY: every view is a live, distinct XLA buffer of this call, checked for dtype and shape.
    let out = unsafe {
        Outputs {
            values: as_slice(values, dtype::F64, "values")?,
            times: as_slice(times, dtype::F64, "event times")?,
            n_events: as_slice(n_events, dtype::S32, "n_events")?,
            status: as_slice(status, dtype::S32, "status")?,
            jacobians: match (dvalues, dtimes) {
                (Some(dv), Some(dt)) => Some((
                    as_slice(dv, dtype::F64, "value Jacobian")?,
                    as_slice(dt, dtype::F64, "event time Jacobian")?,
                )),
                _ => None,
            },
        }
    };
    // SAFETY: the input buffer, read only.
    let p: &[f64] = unsafe { as_input(&p, dtype::F64, "the parameters")? };
    function.run_batch(p, batch, out);
    Ok(())
}
