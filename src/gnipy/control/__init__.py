"""Control and identification: systems driven by inputs, models fitted to data, and inputs chosen
to steer them.

- forces and inputs: a System's generalized force $F(b, v, u, t)$ (:mod:`gnipy.forcing`) enters a
  simulation through :func:`gnipy.simulate`'s `controls=` (the driver's, not this package's);
- :mod:`gnipy.control.identification`: :func:`fit` estimates model parameters and/or the
  initial condition from observed trajectories (:class:`Observations`: arrays, a Solution, a
  netCDF file; partial and noisy), by least squares through the differentiated simulation, with
  standard errors from the Jacobian (:class:`FitResult`), the quantities and combinations the
  data determine (:class:`Combination`), inside bounds (:mod:`gnipy.control.bounds`);
- :mod:`gnipy.control.optimal_control`: :func:`solve_optimal_control` chooses per-step inputs that
  steer a system to a terminal target at least cost, with the GNI's steps as the dynamics (direct
  single or multiple shooting; :class:`ControlResult`);
- the steps of both: :mod:`gnipy.control.fit_arguments`, :mod:`gnipy.control.least_squares` and
  :mod:`gnipy.control.fit_result` (the fit's checked arguments, its least-squares problem, its
  result and statistics), :mod:`gnipy.control.control_arguments`,
  :mod:`gnipy.control.control_result`, :mod:`gnipy.control.shooting` and :mod:`gnipy.control.sqp`
  (the solve's checked arguments and target, its result, the shooting transcriptions, and the
  staged SQP);
- :mod:`gnipy.control.problems`: optimal-control problems as TOML files (`gni control`), the
  worked problems (:data:`WORKED_PROBLEMS`) and the result file; :mod:`gnipy.control.fit_problems`
  the same for identification (`gni fit`); :mod:`gnipy.control.problem_files` reads both kinds of
  file and checks their entries;
- :mod:`gnipy.control.memory`: the memory both are estimated to need, bounded before anything is
  compiled.
"""

from .fit_problems import FitProblem, load_fit_problem, write_fit_result
from .fit_result import Combination
from .identification import FitResult, Observations, fit
from .optimal_control import ControlResult, solve_optimal_control, terminal_residual
from .problems import WORKED_PROBLEMS, ControlProblem, load_problem, worked_problem, write_control_result

__all__ = ["fit", "FitResult", "Combination", "Observations", "solve_optimal_control", "ControlResult", "terminal_residual",
           "ControlProblem", "load_problem", "worked_problem", "write_control_result", "WORKED_PROBLEMS", "FitProblem",
           "load_fit_problem", "write_fit_result"]
