"""Recovering pose, scale and shape from point clouds (paper §4.5).

Modules, in the order of the data flow: ``result`` (:class:`FitResult`), ``problem``
(validated inputs, residuals, Jacobian, robust losses), ``lm`` (the Levenberg-Marquardt
iteration, visibility term and escape step), ``bias`` (noise-bias correction),
``stages`` (the staged ``solver='lm'`` engine), ``scipy_engine`` (``solver='scipy'``),
``init`` (the global initialisation of ``multistart=True``), ``quality`` (the success
test of :attr:`FitResult.success`), ``api`` (:func:`fit` and
``loss='auto'``), ``icp`` (the ICP baseline), ``images`` (:func:`fit_depth` and
:func:`fit_silhouette`: depth images and masks) and ``track`` (:func:`track`: depth
video).
"""

from .api import check_fit, fit
from .icp import icp
from .images import backproject, fit_depth, fit_silhouette
from .result import FitResult
from .track import Tracker, TrackFrame, TrackResult, track

__all__ = ["fit", "check_fit", "icp", "FitResult", "fit_depth", "fit_silhouette",
           "backproject", "track", "Tracker", "TrackResult", "TrackFrame"]
