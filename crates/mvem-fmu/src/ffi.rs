//! The FMI 2.0 C ABI (hand-written `fmi2Functions.h` equivalents).
//!
//! # Safety
//!
//! Every function is called by an FMI importer with the pointers the FMI 2.0 standard
//! describes: `c` is a pointer returned by [`fmi2Instantiate`] and not yet freed, arrays have at
//! least the stated number of elements, strings are NUL-terminated. Null pointers are detected
//! and refused with `fmi2Error`. Every body runs inside `catch_unwind`: a panic never crosses the
//! boundary; it is reported as `fmi2Error` and the instance is marked failed.
#![allow(clippy::missing_safety_doc, non_snake_case, non_camel_case_types)]

use crate::instance::{FmuError, Instance, Interface, Phase, Severity};
use crate::vars::{self, FmuConfig};
use std::ffi::{c_char, c_int, c_void, CStr, CString};
use std::panic::{catch_unwind, AssertUnwindSafe};

/// fmi2Component.
pub type fmi2Component = *mut c_void;
/// fmi2ComponentEnvironment.
pub type fmi2ComponentEnvironment = *mut c_void;
/// fmi2FMUstate.
pub type fmi2FMUstate = *mut c_void;
/// fmi2ValueReference.
pub type fmi2ValueReference = u32;
/// fmi2Real.
pub type fmi2Real = f64;
/// fmi2Integer.
pub type fmi2Integer = c_int;
/// fmi2Boolean.
pub type fmi2Boolean = c_int;
/// fmi2String.
pub type fmi2String = *const c_char;
/// fmi2Byte.
pub type fmi2Byte = c_char;
/// fmi2Status (fmi2OK = 0, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal, fmi2Pending).
pub type fmi2Status = c_int;
/// fmi2OK.
pub const FMI2_OK: fmi2Status = 0;
/// fmi2Discard.
pub const FMI2_DISCARD: fmi2Status = 2;
/// fmi2Error.
pub const FMI2_ERROR: fmi2Status = 3;
/// fmi2Type: fmi2ModelExchange = 0, fmi2CoSimulation = 1.
pub type fmi2Type = c_int;
/// fmi2StatusKind.
pub type fmi2StatusKind = c_int;

/// fmi2CallbackLogger (variadic printf-style; called with "%s" and the message).
pub type fmi2CallbackLogger = Option<
    unsafe extern "C" fn(
        fmi2ComponentEnvironment,
        fmi2String,
        fmi2Status,
        fmi2String,
        fmi2String,
        ...
    ),
>;

/// fmi2CallbackFunctions.
#[repr(C)]
pub struct fmi2CallbackFunctions {
    /// Logger.
    pub logger: fmi2CallbackLogger,
    /// allocateMemory (unused: the instance lives in Rust's allocator).
    pub allocate_memory: Option<unsafe extern "C" fn(usize, usize) -> *mut c_void>,
    /// freeMemory (unused).
    pub free_memory: Option<unsafe extern "C" fn(*mut c_void)>,
    /// stepFinished (unused: fmi2DoStep is synchronous).
    pub step_finished: Option<unsafe extern "C" fn(fmi2ComponentEnvironment, fmi2Status)>,
    /// componentEnvironment.
    pub component_environment: fmi2ComponentEnvironment,
}

/// fmi2EventInfo.
#[repr(C)]
pub struct fmi2EventInfo {
    /// newDiscreteStatesNeeded.
    pub new_discrete_states_needed: fmi2Boolean,
    /// terminateSimulation.
    pub terminate_simulation: fmi2Boolean,
    /// nominalsOfContinuousStatesChanged.
    pub nominals_changed: fmi2Boolean,
    /// valuesOfContinuousStatesChanged.
    pub values_changed: fmi2Boolean,
    /// nextEventTimeDefined.
    pub next_event_time_defined: fmi2Boolean,
    /// nextEventTime.
    pub next_event_time: fmi2Real,
}

/// What an `fmi2Component` points to.
struct Component {
    inst: Instance,
    name: CString,
    logger: fmi2CallbackLogger,
    env: fmi2ComponentEnvironment,
    logging_on: bool,
}

impl Component {
    fn log(&self, status: fmi2Status, category: &str, msg: &str) {
        if status == FMI2_OK && !self.logging_on {
            return;
        }
        if let Some(logger) = self.logger {
            let cat = CString::new(category).unwrap_or_default();
            let m = CString::new(msg.replace('\0', " ")).unwrap_or_default();
            // SAFETY: the importer's logger is printf-like; "%s" with one C string is valid.
            unsafe {
                logger(
                    self.env,
                    self.name.as_ptr(),
                    status,
                    cat.as_ptr(),
                    c"%s".as_ptr(),
                    m.as_ptr(),
                )
            };
        }
    }

    fn fail(&mut self, e: FmuError) -> fmi2Status {
        let status = match e.severity {
            Severity::Discard => FMI2_DISCARD,
            Severity::Error => FMI2_ERROR,
        };
        self.log(
            status,
            if status == FMI2_ERROR {
                "logStatusError"
            } else {
                "logStatusDiscard"
            },
            &e.message,
        );
        status
    }
}

/// Run `f` on the component behind `c`, converting errors and panics to statuses.
unsafe fn with(
    c: fmi2Component,
    f: impl FnOnce(&mut Instance) -> Result<(), FmuError>,
) -> fmi2Status {
    if c.is_null() {
        return FMI2_ERROR;
    }
    // SAFETY: c came from fmi2Instantiate (contract of the ABI).
    let comp = unsafe { &mut *(c as *mut Component) };
    if comp.inst.phase == Phase::Failed {
        comp.log(
            FMI2_ERROR,
            "logStatusError",
            "the instance failed earlier; call fmi2Reset or fmi2FreeInstance",
        );
        return FMI2_ERROR;
    }
    match catch_unwind(AssertUnwindSafe(|| f(&mut comp.inst))) {
        Ok(Ok(())) => FMI2_OK,
        Ok(Err(e)) => comp.fail(e),
        Err(_) => {
            comp.inst.phase = Phase::Failed;
            comp.fail(FmuError {
                severity: Severity::Error,
                message: "internal error (panic) inside the FMU; please report it".into(),
            })
        }
    }
}

fn null(what: &str) -> FmuError {
    FmuError {
        severity: Severity::Error,
        message: format!("{what}: null pointer argument"),
    }
}

/// View `n` elements at `p` (null allowed only for `n == 0`).
unsafe fn slice<'a, T>(p: *const T, n: usize, what: &str) -> Result<&'a [T], FmuError> {
    if n == 0 {
        return Ok(&[]);
    }
    if p.is_null() {
        return Err(null(what));
    }
    // SAFETY: the importer passes arrays of n elements.
    Ok(unsafe { std::slice::from_raw_parts(p, n) })
}

unsafe fn slice_mut<'a, T>(p: *mut T, n: usize, what: &str) -> Result<&'a mut [T], FmuError> {
    if n == 0 {
        return Ok(&mut []);
    }
    if p.is_null() {
        return Err(null(what));
    }
    // SAFETY: the importer passes arrays of n elements.
    Ok(unsafe { std::slice::from_raw_parts_mut(p, n) })
}

fn unsupported(what: &str) -> FmuError {
    FmuError {
        severity: Severity::Error,
        message: format!("{what} is not supported by this FMU (see its capability flags)"),
    }
}

/// Decode `%XX` escapes of a URI path.
fn percent_decode(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' && i + 2 < b.len() {
            let hex = std::str::from_utf8(&b[i + 1..i + 3]).unwrap_or("");
            if let Ok(v) = u8::from_str_radix(hex, 16) {
                out.push(v);
                i += 3;
                continue;
            }
        }
        out.push(b[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// The local folder of an `fmuResourceLocation` URI (`file:///dir`, `file:/dir`,
/// `file://localhost/dir`, or a plain path).
pub fn resource_dir(location: &str) -> std::path::PathBuf {
    let path = if let Some(rest) = location.strip_prefix("file://") {
        rest.strip_prefix("localhost").unwrap_or(rest)
    } else if let Some(rest) = location.strip_prefix("file:") {
        rest
    } else {
        location
    };
    std::path::PathBuf::from(percent_decode(path))
}

/// Read `resources/mvem.json` from the resource location.
fn read_config(location: &str) -> Result<FmuConfig, String> {
    let file = resource_dir(location).join(vars::CONFIG_FILE);
    let text = std::fs::read_to_string(&file)
        .map_err(|e| format!("fmi2Instantiate: cannot read {}: {e}", file.display()))?;
    FmuConfig::from_json(&text).map_err(|e| format!("fmi2Instantiate: {e}"))
}

/// fmi2GetTypesPlatform: "default".
#[no_mangle]
pub extern "C" fn fmi2GetTypesPlatform() -> *const c_char {
    c"default".as_ptr()
}

/// fmi2GetVersion: "2.0".
#[no_mangle]
pub extern "C" fn fmi2GetVersion() -> *const c_char {
    c"2.0".as_ptr()
}

/// fmi2Instantiate: returns null on a wrong GUID, unknown type or a panic.
#[no_mangle]
pub unsafe extern "C" fn fmi2Instantiate(
    instance_name: fmi2String,
    fmu_type: fmi2Type,
    guid: fmi2String,
    resource_location: fmi2String,
    functions: *const fmi2CallbackFunctions,
    _visible: fmi2Boolean,
    logging_on: fmi2Boolean,
) -> fmi2Component {
    let r = catch_unwind(|| {
        let (logger, env) = if functions.is_null() {
            (None, std::ptr::null_mut())
        } else {
            // SAFETY: importer-provided callback struct.
            let f = unsafe { &*functions };
            (f.logger, f.component_environment)
        };
        let name = if instance_name.is_null() {
            CString::new("mvem").unwrap_or_default()
        } else {
            // SAFETY: NUL-terminated string from the importer.
            unsafe { CStr::from_ptr(instance_name) }.to_owned()
        };
        let interface = match fmu_type {
            0 => Some(Interface::ModelExchange),
            1 => Some(Interface::CoSimulation),
            _ => None,
        };
        let config = if resource_location.is_null() {
            Err("fmi2Instantiate: fmuResourceLocation is null".to_string())
        } else {
            // SAFETY: NUL-terminated string from the importer.
            let loc = unsafe { CStr::from_ptr(resource_location) }.to_string_lossy();
            read_config(&loc)
        };
        let comp = Component {
            inst: Instance::new(
                interface.unwrap_or(Interface::CoSimulation),
                config.as_ref().unwrap_or(&FmuConfig::default()),
            ),
            name,
            logger,
            env,
            logging_on: logging_on != 0,
        };
        let Some(_) = interface else {
            comp.log(
                FMI2_ERROR,
                "logStatusError",
                &format!("fmi2Instantiate: unknown fmuType {fmu_type}"),
            );
            return std::ptr::null_mut();
        };
        let config = match config {
            Ok(c) => c,
            Err(e) => {
                comp.log(FMI2_ERROR, "logStatusError", &e);
                return std::ptr::null_mut();
            }
        };
        if interface == Some(Interface::ModelExchange) && !config.model_exchange() {
            comp.log(
                FMI2_ERROR,
                "logStatusError",
                "fmi2Instantiate: this FMU was built with --cylinder-temp one-iteration, which is offered for Co-Simulation only (the one-iteration right-hand side depends on the solver's step sequence)",
            );
            return std::ptr::null_mut();
        }
        let g = if guid.is_null() {
            String::new()
        } else {
            // SAFETY: NUL-terminated string from the importer.
            unsafe { CStr::from_ptr(guid) }
                .to_string_lossy()
                .into_owned()
        };
        let expected = vars::guid(&config);
        if g != expected {
            comp.log(
                FMI2_ERROR,
                "logStatusError",
                &format!(
                    "fmi2Instantiate: GUID {g} does not match {expected} of this binary and resources/{}",
                    vars::CONFIG_FILE
                ),
            );
            return std::ptr::null_mut();
        }
        Box::into_raw(Box::new(comp)) as fmi2Component
    });
    r.unwrap_or(std::ptr::null_mut())
}

/// fmi2FreeInstance.
#[no_mangle]
pub unsafe extern "C" fn fmi2FreeInstance(c: fmi2Component) {
    if !c.is_null() {
        let _ = catch_unwind(|| {
            // SAFETY: c came from Box::into_raw in fmi2Instantiate and is freed once.
            drop(unsafe { Box::from_raw(c as *mut Component) });
        });
    }
}

/// fmi2SetDebugLogging: switches info messages on or off (errors are always logged).
#[no_mangle]
pub unsafe extern "C" fn fmi2SetDebugLogging(
    c: fmi2Component,
    logging_on: fmi2Boolean,
    _n: usize,
    _categories: *const fmi2String,
) -> fmi2Status {
    if c.is_null() {
        return FMI2_ERROR;
    }
    // SAFETY: c came from fmi2Instantiate.
    let comp = unsafe { &mut *(c as *mut Component) };
    comp.logging_on = logging_on != 0;
    FMI2_OK
}

/// fmi2SetupExperiment.
#[no_mangle]
pub unsafe extern "C" fn fmi2SetupExperiment(
    c: fmi2Component,
    tolerance_defined: fmi2Boolean,
    tolerance: fmi2Real,
    start_time: fmi2Real,
    stop_time_defined: fmi2Boolean,
    stop_time: fmi2Real,
) -> fmi2Status {
    with(c, |i| {
        i.setup_experiment(
            (tolerance_defined != 0).then_some(tolerance),
            start_time,
            (stop_time_defined != 0).then_some(stop_time),
        )
    })
}

/// fmi2EnterInitializationMode.
#[no_mangle]
pub unsafe extern "C" fn fmi2EnterInitializationMode(c: fmi2Component) -> fmi2Status {
    with(c, |i| i.enter_initialization())
}

/// fmi2ExitInitializationMode: the states are the steady state at the current inputs.
#[no_mangle]
pub unsafe extern "C" fn fmi2ExitInitializationMode(c: fmi2Component) -> fmi2Status {
    with(c, |i| i.exit_initialization())
}

/// fmi2Terminate.
#[no_mangle]
pub unsafe extern "C" fn fmi2Terminate(c: fmi2Component) -> fmi2Status {
    with(c, |i| i.terminate())
}

/// fmi2Reset (also recovers a failed instance).
#[no_mangle]
pub unsafe extern "C" fn fmi2Reset(c: fmi2Component) -> fmi2Status {
    if c.is_null() {
        return FMI2_ERROR;
    }
    // SAFETY: c came from fmi2Instantiate.
    let comp = unsafe { &mut *(c as *mut Component) };
    match catch_unwind(AssertUnwindSafe(|| comp.inst.reset())) {
        Ok(()) => FMI2_OK,
        Err(_) => FMI2_ERROR,
    }
}

/// fmi2GetReal.
#[no_mangle]
pub unsafe extern "C" fn fmi2GetReal(
    c: fmi2Component,
    vr: *const fmi2ValueReference,
    nvr: usize,
    value: *mut fmi2Real,
) -> fmi2Status {
    with(c, |i| {
        let vr = unsafe { slice(vr, nvr, "fmi2GetReal") }?;
        let out = unsafe { slice_mut(value, nvr, "fmi2GetReal") }?;
        i.get_real(vr, out)
    })
}

/// fmi2SetReal (inputs and parameters).
#[no_mangle]
pub unsafe extern "C" fn fmi2SetReal(
    c: fmi2Component,
    vr: *const fmi2ValueReference,
    nvr: usize,
    value: *const fmi2Real,
) -> fmi2Status {
    with(c, |i| {
        let vr = unsafe { slice(vr, nvr, "fmi2SetReal") }?;
        let v = unsafe { slice(value, nvr, "fmi2SetReal") }?;
        i.set_real(vr, v)
    })
}

fn no_vars(kind: &str, nvr: usize) -> Result<(), FmuError> {
    if nvr == 0 {
        Ok(())
    } else {
        Err(FmuError {
            severity: Severity::Error,
            message: format!(
                "{kind}: the FMU has no variables of this type (unknown value reference)"
            ),
        })
    }
}

/// fmi2GetInteger: there are no Integer variables.
#[no_mangle]
pub unsafe extern "C" fn fmi2GetInteger(
    c: fmi2Component,
    _vr: *const fmi2ValueReference,
    nvr: usize,
    _value: *mut fmi2Integer,
) -> fmi2Status {
    with(c, |_| no_vars("fmi2GetInteger", nvr))
}

/// fmi2SetInteger: there are no Integer variables.
#[no_mangle]
pub unsafe extern "C" fn fmi2SetInteger(
    c: fmi2Component,
    _vr: *const fmi2ValueReference,
    nvr: usize,
    _value: *const fmi2Integer,
) -> fmi2Status {
    with(c, |_| no_vars("fmi2SetInteger", nvr))
}

/// fmi2GetBoolean: there are no Boolean variables.
#[no_mangle]
pub unsafe extern "C" fn fmi2GetBoolean(
    c: fmi2Component,
    _vr: *const fmi2ValueReference,
    nvr: usize,
    _value: *mut fmi2Boolean,
) -> fmi2Status {
    with(c, |_| no_vars("fmi2GetBoolean", nvr))
}

/// fmi2SetBoolean: there are no Boolean variables.
#[no_mangle]
pub unsafe extern "C" fn fmi2SetBoolean(
    c: fmi2Component,
    _vr: *const fmi2ValueReference,
    nvr: usize,
    _value: *const fmi2Boolean,
) -> fmi2Status {
    with(c, |_| no_vars("fmi2SetBoolean", nvr))
}

/// fmi2GetString: there are no String variables.
#[no_mangle]
pub unsafe extern "C" fn fmi2GetString(
    c: fmi2Component,
    _vr: *const fmi2ValueReference,
    nvr: usize,
    _value: *mut fmi2String,
) -> fmi2Status {
    with(c, |_| no_vars("fmi2GetString", nvr))
}

/// fmi2SetString: there are no String variables.
#[no_mangle]
pub unsafe extern "C" fn fmi2SetString(
    c: fmi2Component,
    _vr: *const fmi2ValueReference,
    nvr: usize,
    _value: *const fmi2String,
) -> fmi2Status {
    with(c, |_| no_vars("fmi2SetString", nvr))
}

/// fmi2GetFMUstate: not supported (canGetAndSetFMUstate = false).
#[no_mangle]
pub unsafe extern "C" fn fmi2GetFMUstate(c: fmi2Component, _s: *mut fmi2FMUstate) -> fmi2Status {
    with(c, |_| Err(unsupported("fmi2GetFMUstate")))
}

/// fmi2SetFMUstate: not supported.
#[no_mangle]
pub unsafe extern "C" fn fmi2SetFMUstate(c: fmi2Component, _s: fmi2FMUstate) -> fmi2Status {
    with(c, |_| Err(unsupported("fmi2SetFMUstate")))
}

/// fmi2FreeFMUstate: not supported.
#[no_mangle]
pub unsafe extern "C" fn fmi2FreeFMUstate(c: fmi2Component, _s: *mut fmi2FMUstate) -> fmi2Status {
    with(c, |_| Err(unsupported("fmi2FreeFMUstate")))
}

/// fmi2SerializedFMUstateSize: not supported.
#[no_mangle]
pub unsafe extern "C" fn fmi2SerializedFMUstateSize(
    c: fmi2Component,
    _s: fmi2FMUstate,
    _size: *mut usize,
) -> fmi2Status {
    with(c, |_| Err(unsupported("fmi2SerializedFMUstateSize")))
}

/// fmi2SerializeFMUstate: not supported.
#[no_mangle]
pub unsafe extern "C" fn fmi2SerializeFMUstate(
    c: fmi2Component,
    _s: fmi2FMUstate,
    _bytes: *mut fmi2Byte,
    _size: usize,
) -> fmi2Status {
    with(c, |_| Err(unsupported("fmi2SerializeFMUstate")))
}

/// fmi2DeSerializeFMUstate: not supported.
#[no_mangle]
pub unsafe extern "C" fn fmi2DeSerializeFMUstate(
    c: fmi2Component,
    _bytes: *const fmi2Byte,
    _size: usize,
    _s: *mut fmi2FMUstate,
) -> fmi2Status {
    with(c, |_| Err(unsupported("fmi2DeSerializeFMUstate")))
}

/// fmi2GetDirectionalDerivative (providesDirectionalDerivative = true): see
/// [`Instance::directional_derivative`].
#[no_mangle]
pub unsafe extern "C" fn fmi2GetDirectionalDerivative(
    c: fmi2Component,
    vu: *const fmi2ValueReference,
    nu: usize,
    vk: *const fmi2ValueReference,
    nk: usize,
    dvk: *const fmi2Real,
    dvu: *mut fmi2Real,
) -> fmi2Status {
    with(c, |i| {
        const WHAT: &str = "fmi2GetDirectionalDerivative";
        let vu = unsafe { slice(vu, nu, WHAT) }?;
        let vk = unsafe { slice(vk, nk, WHAT) }?;
        let dvk = unsafe { slice(dvk, nk, WHAT) }?;
        let dvu = unsafe { slice_mut(dvu, nu, WHAT) }?;
        i.directional_derivative(vu, vk, dvk, dvu)
    })
}

// ---------------------------------------------------------------- Model Exchange

/// fmi2EnterEventMode.
#[no_mangle]
pub unsafe extern "C" fn fmi2EnterEventMode(c: fmi2Component) -> fmi2Status {
    with(c, |i| i.enter_event_mode())
}

/// fmi2NewDiscreteStates: no discrete states; the next delayed actuator-command jump is a
/// time event.
#[no_mangle]
pub unsafe extern "C" fn fmi2NewDiscreteStates(
    c: fmi2Component,
    info: *mut fmi2EventInfo,
) -> fmi2Status {
    with(c, |i| {
        if info.is_null() {
            return Err(null("fmi2NewDiscreteStates"));
        }
        let ev = i.new_discrete_states()?;
        // SAFETY: non-null pointer to the importer's struct.
        let info = unsafe { &mut *info };
        info.new_discrete_states_needed = 0;
        info.terminate_simulation = 0;
        info.nominals_changed = 0;
        info.values_changed = 0;
        info.next_event_time_defined = ev.next_event_time.is_some() as fmi2Boolean;
        info.next_event_time = ev.next_event_time.unwrap_or(0.0);
        Ok(())
    })
}

/// fmi2EnterContinuousTimeMode.
#[no_mangle]
pub unsafe extern "C" fn fmi2EnterContinuousTimeMode(c: fmi2Component) -> fmi2Status {
    with(c, |i| i.enter_continuous_time_mode())
}

/// fmi2CompletedIntegratorStep: never requests an event.
#[no_mangle]
pub unsafe extern "C" fn fmi2CompletedIntegratorStep(
    c: fmi2Component,
    _no_set_fmu_state_prior: fmi2Boolean,
    enter_event_mode: *mut fmi2Boolean,
    terminate_simulation: *mut fmi2Boolean,
) -> fmi2Status {
    with(c, |i| {
        if enter_event_mode.is_null() || terminate_simulation.is_null() {
            return Err(null("fmi2CompletedIntegratorStep"));
        }
        i.completed_integrator_step()?;
        // SAFETY: non-null pointers to the importer's booleans.
        unsafe {
            *enter_event_mode = 0;
            *terminate_simulation = 0;
        }
        Ok(())
    })
}

/// fmi2SetTime.
#[no_mangle]
pub unsafe extern "C" fn fmi2SetTime(c: fmi2Component, time: fmi2Real) -> fmi2Status {
    with(c, |i| i.set_time(time))
}

/// fmi2SetContinuousStates.
#[no_mangle]
pub unsafe extern "C" fn fmi2SetContinuousStates(
    c: fmi2Component,
    x: *const fmi2Real,
    nx: usize,
) -> fmi2Status {
    with(c, |i| {
        let x = unsafe { slice(x, nx, "fmi2SetContinuousStates") }?;
        i.set_states(x)
    })
}

/// fmi2GetDerivatives.
#[no_mangle]
pub unsafe extern "C" fn fmi2GetDerivatives(
    c: fmi2Component,
    dx: *mut fmi2Real,
    nx: usize,
) -> fmi2Status {
    with(c, |i| {
        let dx = unsafe { slice_mut(dx, nx, "fmi2GetDerivatives") }?;
        i.get_derivatives(dx)
    })
}

/// fmi2GetEventIndicators: there are none (ni must be 0).
#[no_mangle]
pub unsafe extern "C" fn fmi2GetEventIndicators(
    c: fmi2Component,
    _z: *mut fmi2Real,
    ni: usize,
) -> fmi2Status {
    with(c, |_| {
        if ni == 0 {
            Ok(())
        } else {
            Err(FmuError {
                severity: Severity::Error,
                message: format!("fmi2GetEventIndicators: ni = {ni} (the FMU has 0)"),
            })
        }
    })
}

/// fmi2GetContinuousStates.
#[no_mangle]
pub unsafe extern "C" fn fmi2GetContinuousStates(
    c: fmi2Component,
    x: *mut fmi2Real,
    nx: usize,
) -> fmi2Status {
    with(c, |i| {
        let x = unsafe { slice_mut(x, nx, "fmi2GetContinuousStates") }?;
        i.get_states(x)
    })
}

/// fmi2GetNominalsOfContinuousStates.
#[no_mangle]
pub unsafe extern "C" fn fmi2GetNominalsOfContinuousStates(
    c: fmi2Component,
    x_nominal: *mut fmi2Real,
    nx: usize,
) -> fmi2Status {
    with(c, |i| {
        let x = unsafe { slice_mut(x_nominal, nx, "fmi2GetNominalsOfContinuousStates") }?;
        i.nominals(x)
    })
}

// ---------------------------------------------------------------- Co-Simulation

/// fmi2SetRealInputDerivatives: not supported (canInterpolateInputs = false).
#[no_mangle]
pub unsafe extern "C" fn fmi2SetRealInputDerivatives(
    c: fmi2Component,
    _vr: *const fmi2ValueReference,
    _nvr: usize,
    _order: *const fmi2Integer,
    _value: *const fmi2Real,
) -> fmi2Status {
    with(c, |_| Err(unsupported("fmi2SetRealInputDerivatives")))
}

/// fmi2GetRealOutputDerivatives: not supported (maxOutputDerivativeOrder = 0).
#[no_mangle]
pub unsafe extern "C" fn fmi2GetRealOutputDerivatives(
    c: fmi2Component,
    _vr: *const fmi2ValueReference,
    _nvr: usize,
    _order: *const fmi2Integer,
    _value: *mut fmi2Real,
) -> fmi2Status {
    with(c, |_| Err(unsupported("fmi2GetRealOutputDerivatives")))
}

/// fmi2DoStep: integrates with mvem's own error-controlled integrator, inputs held constant
/// over the step, transport delays from the input history.
#[no_mangle]
pub unsafe extern "C" fn fmi2DoStep(
    c: fmi2Component,
    current_communication_point: fmi2Real,
    communication_step_size: fmi2Real,
    _no_set_fmu_state_prior: fmi2Boolean,
) -> fmi2Status {
    with(c, |i| {
        i.do_step(current_communication_point, communication_step_size)
    })
}

/// fmi2CancelStep: steps are synchronous; nothing to cancel.
#[no_mangle]
pub unsafe extern "C" fn fmi2CancelStep(c: fmi2Component) -> fmi2Status {
    with(c, |_| {
        Err(unsupported("fmi2CancelStep (steps are synchronous)"))
    })
}

/// fmi2GetStatus: not supported (no asynchronous steps).
#[no_mangle]
pub unsafe extern "C" fn fmi2GetStatus(
    c: fmi2Component,
    _s: fmi2StatusKind,
    _value: *mut fmi2Status,
) -> fmi2Status {
    with(c, |_| Err(unsupported("fmi2GetStatus")))
}

/// fmi2GetRealStatus: `fmi2LastSuccessfulTime` (kind 2) gives the FMU time.
#[no_mangle]
pub unsafe extern "C" fn fmi2GetRealStatus(
    c: fmi2Component,
    s: fmi2StatusKind,
    value: *mut fmi2Real,
) -> fmi2Status {
    with(c, |i| {
        if value.is_null() {
            return Err(null("fmi2GetRealStatus"));
        }
        if s != 2 {
            return Err(unsupported("fmi2GetRealStatus for this status kind"));
        }
        // SAFETY: non-null pointer from the importer.
        unsafe { *value = i.time() };
        Ok(())
    })
}

/// fmi2GetIntegerStatus: not supported.
#[no_mangle]
pub unsafe extern "C" fn fmi2GetIntegerStatus(
    c: fmi2Component,
    _s: fmi2StatusKind,
    _value: *mut fmi2Integer,
) -> fmi2Status {
    with(c, |_| Err(unsupported("fmi2GetIntegerStatus")))
}

/// fmi2GetBooleanStatus: not supported.
#[no_mangle]
pub unsafe extern "C" fn fmi2GetBooleanStatus(
    c: fmi2Component,
    _s: fmi2StatusKind,
    _value: *mut fmi2Boolean,
) -> fmi2Status {
    with(c, |_| Err(unsupported("fmi2GetBooleanStatus")))
}

/// fmi2GetStringStatus: not supported.
#[no_mangle]
pub unsafe extern "C" fn fmi2GetStringStatus(
    c: fmi2Component,
    _s: fmi2StatusKind,
    _value: *mut fmi2String,
) -> fmi2Status {
    with(c, |_| Err(unsupported("fmi2GetStringStatus")))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// fmi2Instantiate without callbacks (type 0 = Model Exchange, 1 = Co-Simulation).
    unsafe fn inst(fmu_type: fmi2Type, guid: fmi2String, location: fmi2String) -> fmi2Component {
        unsafe {
            fmi2Instantiate(
                c"x".as_ptr(),
                fmu_type,
                guid,
                location,
                std::ptr::null(),
                0,
                0,
            )
        }
    }

    #[test]
    fn null_and_wrong_guid_are_refused() {
        unsafe {
            assert_eq!(
                fmi2EnterInitializationMode(std::ptr::null_mut()),
                FMI2_ERROR
            );
            let c = inst(1, c"{wrong}".as_ptr(), std::ptr::null());
            assert!(c.is_null());
            let cfg = FmuConfig::default();
            let g = CString::new(vars::guid(&cfg)).unwrap();
            // no resource location, and one without mvem.json: refused
            for loc in [std::ptr::null(), c"file:///nonexistent/resources".as_ptr()] {
                let c = inst(1, g.as_ptr(), loc);
                assert!(c.is_null());
            }
            let dir = std::env::temp_dir().join(format!("mvem-fmu-test-{}", std::process::id()));
            std::fs::create_dir_all(&dir).unwrap();
            std::fs::write(dir.join(vars::CONFIG_FILE), cfg.to_json()).unwrap();
            let loc = CString::new(format!("file://{}", dir.display())).unwrap();
            let c = inst(1, g.as_ptr(), loc.as_ptr());
            assert!(!c.is_null());
            assert_eq!(
                fmi2GetReal(c, std::ptr::null(), 1, std::ptr::null_mut()),
                FMI2_ERROR
            );
            assert_eq!(fmi2DoStep(c, 0.0, 0.1, 1), FMI2_ERROR); // not initialized
            assert_eq!(fmi2SetupExperiment(c, 0, 0.0, 0.0, 0, 0.0), FMI2_OK);
            assert_eq!(fmi2EnterInitializationMode(c), FMI2_OK);
            assert_eq!(fmi2ExitInitializationMode(c), FMI2_OK);
            let vr = [vars::VR_STATE];
            let mut v = [0.0];
            assert_eq!(fmi2GetReal(c, vr.as_ptr(), 1, v.as_mut_ptr()), FMI2_OK);
            assert!(v[0] > 1e5);
            assert_eq!(fmi2DoStep(c, 0.0, 0.1, 1), FMI2_OK);
            let nan = [f64::NAN];
            let vin = [vars::VR_INPUT];
            assert_eq!(fmi2SetReal(c, vin.as_ptr(), 1, nan.as_ptr()), FMI2_ERROR);
            assert_eq!(
                fmi2GetInteger(c, vr.as_ptr(), 1, std::ptr::null_mut()),
                FMI2_ERROR
            );
            assert_eq!(
                fmi2GetInteger(c, vr.as_ptr(), 0, std::ptr::null_mut()),
                FMI2_OK
            );
            fmi2FreeInstance(c);
            // a one-iteration configuration refuses Model Exchange
            let oi = FmuConfig {
                cylinder_temp: mvem::model::CylinderTemp::OneIteration,
                ..FmuConfig::default()
            };
            std::fs::write(dir.join(vars::CONFIG_FILE), oi.to_json()).unwrap();
            let g = CString::new(vars::guid(&oi)).unwrap();
            let me = inst(0, g.as_ptr(), loc.as_ptr());
            assert!(me.is_null());
            let cs = inst(1, g.as_ptr(), loc.as_ptr());
            assert!(!cs.is_null());
            fmi2FreeInstance(cs);
            let _ = std::fs::remove_dir_all(&dir);
        }
    }

    #[test]
    fn resource_locations_decode_to_paths() {
        let p = std::path::PathBuf::from;
        assert_eq!(
            resource_dir("file:///tmp/a%20b/resources"),
            p("/tmp/a b/resources")
        );
        assert_eq!(resource_dir("file:/tmp/x"), p("/tmp/x"));
        assert_eq!(resource_dir("file://localhost/tmp/x"), p("/tmp/x"));
        assert_eq!(resource_dir("/tmp/x%"), p("/tmp/x%"));
        assert_eq!(resource_dir("/tmp/%zz%4"), p("/tmp/%zz%4"));
    }
}
