"""SUNDIALS CVODE, as fmpy ships it, for harness/me_master.py: the integrator of ``--algorithm me``.

fmpy (a dependency already) carries SUNDIALS 7's shared libraries (``fmpy.sundials``) and binds a
part of CVODE for its own ``simulate``.  This module binds the calls the Model Exchange master
makes, on function objects of its own (``prototype((name, library))``), so fmpy's declarations
stay untouched in the same process.  :class:`Cvode` is one integration: BDF (variable order 1-5)
with a dense direct linear solver and CVODE's difference-quotient Jacobian, the scalar relative
tolerance and per-state absolute tolerances, root finding on the event indicators, one internal
step per :meth:`Cvode.step`, and CVODE's own interpolation of the solution at output points
(:meth:`Cvode.interpolate`).  Why BDF (the loop is stiff) and why CVODE:
docs/model_exchange.md#the-integrator-why-cvode-bdf.

The right-hand side and the root function are either Python callables or the addresses of C
functions (harness/me_loop.c): CVODE calls them the same way.
"""
from __future__ import annotations

import ctypes

from fmpy.sundials import libraries as _libraries

CV_ADAMS, CV_BDF = 1, 2
CV_NORMAL, CV_ONE_STEP = 1, 2
CV_SUCCESS, CV_TSTOP_RETURN, CV_ROOT_RETURN = 0, 1, 2

_c = ctypes
_int, _long, _double, _void = _c.c_int, _c.c_long, _c.c_double, _c.c_void_p
RHS_FUNCTION = _c.CFUNCTYPE(_int, _double, _void, _void, _void)  # (t, y, ydot, user_data)
ROOT_FUNCTION = _c.CFUNCTYPE(_int, _double, _void, _void, _void)  # (t, y, gout, user_data)
ERROR_HANDLER = _c.CFUNCTYPE(None, _int, _c.c_char_p, _c.c_char_p, _c.c_char_p, _int, _void, _void)

_core, _cvode = _libraries.sundials_core, _libraries.sundials_cvode
_nvector, _matrix, _solver = (_libraries.sundials_nvecserial, _libraries.sundials_sunmatrixdense,
                              _libraries.sundials_sunlinsoldense)


def _bind(library, name: str, restype, *argtypes):
    return _c.CFUNCTYPE(restype, *argtypes)((name, library))


SUNContext_Create = _bind(_core, "SUNContext_Create", _int, _int, _c.POINTER(_void))
SUNContext_Free = _bind(_core, "SUNContext_Free", _int, _c.POINTER(_void))
SUNContext_ClearErrHandlers = _bind(_core, "SUNContext_ClearErrHandlers", _int, _void)
SUNContext_PushErrHandler = _bind(_core, "SUNContext_PushErrHandler", _int, _void, ERROR_HANDLER, _void)
N_VNew_Serial = _bind(_nvector, "N_VNew_Serial", _void, _c.c_int64, _void)
N_VDestroy = _bind(_core, "N_VDestroy", None, _void)
N_VGetArrayPointer = _bind(_core, "N_VGetArrayPointer", _void, _void)
SUNDenseMatrix = _bind(_matrix, "SUNDenseMatrix", _void, _c.c_int64, _c.c_int64, _void)
SUNMatDestroy = _bind(_core, "SUNMatDestroy", None, _void)
SUNLinSol_Dense = _bind(_solver, "SUNLinSol_Dense", _void, _void, _void, _void)
SUNLinSolFree = _bind(_core, "SUNLinSolFree", _int, _void)
CVodeCreate = _bind(_cvode, "CVodeCreate", _void, _int, _void)
CVodeInit = _bind(_cvode, "CVodeInit", _int, _void, _void, _double, _void)
CVodeReInit = _bind(_cvode, "CVodeReInit", _int, _void, _double, _void)
CVodeSVtolerances = _bind(_cvode, "CVodeSVtolerances", _int, _void, _double, _void)
CVodeRootInit = _bind(_cvode, "CVodeRootInit", _int, _void, _int, _void)
CVodeSetUserData = _bind(_cvode, "CVodeSetUserData", _int, _void, _void)
CVodeSetStopTime = _bind(_cvode, "CVodeSetStopTime", _int, _void, _double)
CVodeSetMaxNumSteps = _bind(_cvode, "CVodeSetMaxNumSteps", _int, _void, _long)
CVodeSetNoInactiveRootWarn = _bind(_cvode, "CVodeSetNoInactiveRootWarn", _int, _void)
CVodeSetLinearSolver = _bind(_cvode, "CVodeSetLinearSolver", _int, _void, _void, _void)
CVode = _bind(_cvode, "CVode", _int, _void, _double, _void, _c.POINTER(_double), _int)
CVodeGetDky = _bind(_cvode, "CVodeGetDky", _int, _void, _double, _int, _void)
CVodeGetRootInfo = _bind(_cvode, "CVodeGetRootInfo", _int, _void, _c.POINTER(_int))
CVodeGetLastOrder = _bind(_cvode, "CVodeGetLastOrder", _int, _void, _c.POINTER(_int))
CVodeGetCurrentTime = _bind(_cvode, "CVodeGetCurrentTime", _int, _void, _c.POINTER(_double))
CVodeGetReturnFlagName = _bind(_cvode, "CVodeGetReturnFlagName", _c.c_char_p, _long)
CVodeFree = _bind(_cvode, "CVodeFree", None, _c.POINTER(_void))
_COUNTERS = {name: _bind(_cvode, f"CVodeGet{name}", _int, _void, _c.POINTER(_long))
             for name in ("NumSteps", "NumRhsEvals", "NumLinRhsEvals", "NumJacEvals", "NumGEvals",
                          "NumErrTestFails", "NumNonlinSolvConvFails")}
#: the statistics the master reports, from CVODE's counters (summed over re-initialisations at events)
STATISTICS = {"steps": ("NumSteps",), "derivative_evaluations": ("NumRhsEvals", "NumLinRhsEvals"),
              "jacobians": ("NumJacEvals",), "root_evaluations": ("NumGEvals",),
              "error_test_failures": ("NumErrTestFails",), "convergence_failures": ("NumNonlinSolvConvFails",)}

MAX_ORDER = 5  # BDF's highest order: the interpolant has at most 6 Taylor coefficients


def address_of(name: str) -> int:
    library = _core if name == "N_VGetArrayPointer" else _cvode
    return _c.cast(getattr(library, name), _void).value


class CvodeError(RuntimeError):
    """CVODE could not be set up or stopped with an error flag; ``flag`` and CVODE's ``message``."""

    def __init__(self, text: str, flag: int = 0, message: str = ""):
        super().__init__(text)
        self.flag, self.message = flag, message


def flag_name(flag: int) -> str:
    name = CVodeGetReturnFlagName(flag)
    return name.decode() if name else str(flag)


class Cvode:
    """One CVODE integration of ``n`` states from ``t0`` (BDF, dense linear solver, DQ Jacobian).

    ``rhs`` and ``roots`` are Python callables ``(t, y, ydot|gout, user_data) -> int`` taking
    addresses, or the integer addresses of C functions of that signature; ``user_data`` is an
    address handed to them (the C loop's state).  ``absolute`` is the per-state absolute tolerance.
    """

    def __init__(self, n: int, t0: float, x0, rtol: float, absolute, rhs, roots=None, indicators: int = 0,
                 user_data: int | None = None, stop: float | None = None):
        self.n, self.indicators = n, indicators
        self.messages = []
        self._closed = False
        self._context = _void()
        self._check(SUNContext_Create(0, _c.byref(self._context)), "SUNContext_Create")
        self._handler = ERROR_HANDLER(self._error)  # kept alive as long as the context
        SUNContext_ClearErrHandlers(self._context)  # no message printed to stderr: they become the failure's reason
        SUNContext_PushErrHandler(self._context, self._handler, None)
        self.y = N_VNew_Serial(n, self._context)
        self._tolerances = N_VNew_Serial(n, self._context)
        self.y_data = (_double * n).from_address(N_VGetArrayPointer(self.y))
        self._interpolated = N_VNew_Serial(n, self._context)
        self.interpolated = (_double * n).from_address(N_VGetArrayPointer(self._interpolated))
        self.y_data[:] = list(x0)
        (_double * n).from_address(N_VGetArrayPointer(self._tolerances))[:] = list(absolute)
        self.memory = CVodeCreate(CV_BDF, self._context)
        if not self.memory:
            raise CvodeError("CVodeCreate failed")
        self._rhs = rhs if isinstance(rhs, int) else RHS_FUNCTION(rhs)
        self._roots = roots if roots is None or isinstance(roots, int) else ROOT_FUNCTION(roots)
        self._check(CVodeInit(self.memory, self._address(self._rhs), t0, self.y), "CVodeInit")
        self._check(CVodeSVtolerances(self.memory, rtol, self._tolerances), "CVodeSVtolerances")
        if user_data is not None:
            self._check(CVodeSetUserData(self.memory, user_data), "CVodeSetUserData")
        if indicators:
            self._check(CVodeRootInit(self.memory, indicators, self._address(self._roots)), "CVodeRootInit")
            CVodeSetNoInactiveRootWarn(self.memory)
        self._matrix = SUNDenseMatrix(n, n, self._context)
        self._solver = SUNLinSol_Dense(self.y, self._matrix, self._context)
        self._check(CVodeSetLinearSolver(self.memory, self._solver, self._matrix), "CVodeSetLinearSolver")
        if stop is not None:
            self._check(CVodeSetStopTime(self.memory, stop), "CVodeSetStopTime")
        self.t = _double(t0)
        self._root_info = (_int * max(indicators, 1))()
        self.totals = dict.fromkeys(STATISTICS, 0)

    @staticmethod
    def _address(function) -> int:
        return function if isinstance(function, int) else _c.cast(function, _void).value

    def _error(self, line, function, file, message, code, user_data, context):
        text = (message or b"").decode("utf-8", "replace").strip()
        where = (function or b"").decode("utf-8", "replace")
        self.messages.append(f"{where}: {text}" if where else text)

    def _check(self, flag: int, call: str):
        if flag < 0:
            detail = f": {self.messages[-1]}" if self.messages else ""
            raise CvodeError(f"{call} returned {flag_name(flag)}{detail}", flag, detail)

    # ------------------------------------------------------------ stepping
    def step(self, t_out: float) -> int:
        """One internal step towards ``t_out`` (CV_ONE_STEP); the flag (>= 0), ``self.t`` the time reached.
        A negative flag is returned, not raised: the caller stops with its rows and :meth:`reason`."""
        return CVode(self.memory, t_out, self.y, _c.byref(self.t), CV_ONE_STEP)

    def interpolate(self, t: float) -> int:
        """The solution at ``t`` inside the last step into ``self.interpolated`` (CVODE's interpolant)."""
        return CVodeGetDky(self.memory, t, 0, self._interpolated)

    def taylor(self, coefficients) -> tuple:
        """The interpolant of the last step as a Taylor polynomial about the time ``tn`` CVODE reached:
        ``coefficients[k] = y^(k)(tn) / k!`` (a numpy array of MAX_ORDER + 1 rows); returns (status, tn,
        order).  harness/me_loop.c computes the same (me_loop_run), so both loops evaluate the same
        polynomial with the same operations: Horner in t - tn."""
        order, tn = _int(), _double()
        CVodeGetLastOrder(self.memory, _c.byref(order))
        CVodeGetCurrentTime(self.memory, _c.byref(tn))
        factorial = 1.0
        for k in range(order.value + 1):
            status = CVodeGetDky(self.memory, tn.value, k, self._interpolated)
            if status < 0:
                return status, tn.value, order.value
            if k:
                factorial *= k
            coefficients[k] = self.interpolated[:self.n]
            coefficients[k] /= factorial
        return 0, tn.value, order.value

    @property
    def interpolated_address(self) -> int:
        return N_VGetArrayPointer(self._interpolated)

    @property
    def y_address(self) -> int:
        return N_VGetArrayPointer(self.y)

    def roots_found(self) -> list:
        """Which indicators crossed zero at the last CV_ROOT_RETURN (+1 rising, -1 falling, 0 none)."""
        self._check(CVodeGetRootInfo(self.memory, self._root_info), "CVodeGetRootInfo")
        return list(self._root_info[:self.indicators])

    def reinit(self, t: float, x=None):
        """Restart at ``t`` from ``x`` (default: the current ``y_data``): after an event."""
        self._accumulate()
        if x is not None:
            _c.memmove(self.y_data, x, 8 * self.n)
        self._check(CVodeReInit(self.memory, t, self.y), "CVodeReInit")
        self.t.value = t

    def reason(self, flag: int) -> str:
        """CVODE's flag name and its last message: the solver's reason for stopping."""
        message = f": {self.messages[-1]}" if self.messages else ""
        return f"{flag_name(flag)}{message}"

    def _counter(self, name: str) -> int:
        value = _long()
        _COUNTERS[name](self.memory, _c.byref(value))
        return value.value

    def _accumulate(self):
        for key, names in STATISTICS.items():
            self.totals[key] += sum(self._counter(name) for name in names)

    def statistics(self) -> dict:
        """CVODE's counters summed over every restart so far (steps, derivative evaluations (with the
        Jacobians' difference quotients), Jacobians, root-function evaluations, error-test and
        convergence failures)."""
        current = {key: sum(self._counter(name) for name in names) for key, names in STATISTICS.items()}
        return {key: self.totals[key] + current[key] for key in STATISTICS}

    def close(self):
        if self._closed:
            return
        self._closed = True
        memory = _void(self.memory)
        CVodeFree(_c.byref(memory))
        SUNLinSolFree(self._solver)
        SUNMatDestroy(self._matrix)
        for vector in (self.y, self._tolerances, self._interpolated):
            N_VDestroy(vector)
        SUNContext_Free(_c.byref(self._context))


__all__ = ["Cvode", "CvodeError", "flag_name", "address_of", "RHS_FUNCTION", "ROOT_FUNCTION", "CV_ROOT_RETURN",
           "CV_TSTOP_RETURN", "CV_SUCCESS"]
