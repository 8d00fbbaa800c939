"""Known models in cluttered scans (paper §4.4): :func:`detect` and
:func:`detections_to_scene`.

The pipeline, for a cloud that holds several objects, a floor or table and clutter:

1. **Neighbourhoods** (:mod:`.neighbours`): normals (turned towards the viewpoint), the
   noise level and the neighbour graph.
2. **Support planes.** :func:`detect_primitives` looks for planes holding at least
   ``SUPPORT_MIN_FRACTION`` of the points; a plane wider than ``SUPPORT_SPAN`` times the
   largest model's diameter is a support (a floor, a table top larger than any model).
   Its points are set aside; the largest support's normal (towards the sensor) is *up*.
3. **Clusters.** The other points split into connected components of the neighbour
   graph (an edge links points no farther apart than ``LINK`` times the local spacing of
   both ends, so isolated outliers join nothing); components of fewer than
   ``min_points`` points are dropped.
4. **Hypotheses per cluster and model**, largest cluster first. With a support, models
   stand upright on it (their +z along *up*, their lowest point on the plane):
   ``YAWS`` turns about *up* at two positions each (the cluster's footprint centre, and
   pushed away from the sensor by a third of the model's radius: a single view sees the
   near side) and ``PARAM_STARTS + 1`` parameter sets (the defaults and the draws of a
   ``PARAM_BANK`` Latin hypercube whose height is nearest the cluster's), scored at
   once, both ways: the robust (Huber) cost of the model's exact
   signed distance at a fixed subsample of the cluster, plus the truncated squared
   distance from each of the model's surface samples that face the sensor to the
   nearest scan point (a model standing where the sensor saw nothing pays; a sample
   hidden behind a nearer scan point does not; the first term bounds the cost from
   below, so the second is computed only for the hypotheses that can still reach the
   best ``REFINE_TOP``: :meth:`_Run._screen`); the best ``REFINE_TOP`` get a few
   pose-only Gauss-Newton steps (:func:`csdf.fit` on the subsample), and the
   ``MODELS_REFINED`` models whose best costs least, those within ``SCREEN_RATIO``
   times the least, go on to step 5. Without a support,
   :func:`csdf.fit`'s ``multistart`` search replaces this step.
5. **Refinement.** The best hypothesis is refined by :func:`csdf.fit` in pose and shape
   parameters (``viewpoint=`` visibility, ``loss='auto'``) on the cluster's points near
   it.
6. **Verification.** The fitted model is ray-cast from the viewpoint against every scan
   point in its direction, the support's included (:func:`csdf.fit.check_fit`): its
   visible surface must be seen (at most ``MAX_SEE_THROUGH`` of it where the sensor saw
   farther, through the model, and at most ``MAX_UNEXPLAINED`` see-through or empty in
   all), and it must explain at least ``min_points`` points (within three noise levels);
   of its own clusters' free points within ``BAND`` noise levels of its surface, at
   least ``MIN_BAND_FRACTION`` must lie within three (the band test); and at most
   ``MAX_AT_BOUND`` of its parameters may lie at an end of their ranges (more:
   something else squeezed into the model).
   Without a viewpoint only the points explained and the inlier rmse are judged.
7. **Competition.** The fits that pass are ranked by their explained mass
   (:func:`_gain` summed over the free points near them, less the free-space evidence
   in the same units); the winner's best other yaw of a ``YAW_STEPS`` scan, and those
   of failed models the screen ranked above it, are fitted again and compete too. The
   winner's inliers are claimed (those of its own clusters, of clusters it mostly
   explains and of none, not a neighbour's points near its surface:
   :meth:`_Run._own_inliers`): other clusters that
   are mostly claimed are skipped (one object split in two by an occluder), and a
   cluster with enough unclaimed points left is searched again (two objects touching);
   a cluster no model explains as one, after the band test rejected a large fit, or
   wider than any model may be, is searched by the halves of its footprint
   (:meth:`_Run.best_in_parts`). A model whose
   fit explained most of the points but failed is fitted again from ``RETRY_STARTS``
   other parameter starts (:meth:`_Run._other_params`); so is a winner with over
   ``REFIT_UNEXPLAINED`` of its visible surface unexplained. Fits in another pose
   within ``TRIM_RIVALS`` of the winner are cut back to their points and held back
   from the ends of their ranges, and compete too (:meth:`_Run._trim_rivals`). A
   cluster whose fits failed after taking another cluster as a piece of their object
   is searched again once a later detection has claimed points of that cluster
   (``RETRY_JOINED``).
8. **Turns resting on a small part** (:meth:`_Run._resolve_yaw`): when the winner's
   model has a turn about its axis, not a symmetry, that moves under ``YAW_DOUBT`` of
   its surface (a lamp's spokes), it is refitted held upright (:meth:`_Run._polish`)
   and its turn chosen by ray casting the sensor's rays (:meth:`_Run._ray_scores`;
   points of its own clusters floating in front of it count against a turn, as rays
   that see through it do; the model's parts dilated by ``RAY_SPREAD`` noise levels
   in the sensor's image, so that spokes fitted a few millimetres off still meet the
   rays that saw them):
   the refit replaces the winner when its rays score more, and another turn replaces
   that when it scores more than the refit's own turn at the refit's parameters.
9. **Points floating inside** (:meth:`_Run._intruders`): a detection with over
   ``MAX_INTRUDERS`` of the points in its box in its free space in front of it (a
   model stretched over something else) is dropped; so is one with over ``MAX_FRONT``
   of the rays on its visible surface showing a point of its own clusters in front
   of it (:meth:`_Run._front_fraction`: a lamp laid over a ball), and so is one whose
   range the scan confirms on under ``MIN_CONFIRMED`` of the rays that hit it (its
   silhouette nearly all hidden or seen through: :meth:`_Run._ray_evidence`).
10. **Overlaps merged** (:func:`_merge_overlaps`): two detections of one model that
    share space (``MERGE_OVERLAP``: a table split in two by an occluder, each half
    found as a short table) are replaced by one fit to both's points when it passes
    and explains ``MERGE_COVER`` of them.
11. **Turns the scan does not settle** (:meth:`_Run.settle_turn`, as each detection is
    found and after a merge): a detection of a model whose turn is in doubt (step 8)
    has its turns ``SETTLE_STEP`` degrees apart over one period of its symmetry
    ray-cast without the spread, its parameters refitted to its rays at the best
    (:meth:`_Run._ray_refit`: Nelder-Mead on the rays' score, ``RAY_REFIT_EVALS``
    evaluations), its turns ray-cast again at those, and takes the best. When that
    leads every turn ``SETTLED_APART`` degrees or more away by under
    ``SETTLED_PLAIN_RAYS`` explained points, its turn is a guess: it is marked
    (:attr:`Detection.settled` False) and left out of the result unless
    ``keep_unsettled`` (its points stay claimed). A detection of another model whose
    half turn is not a symmetry (a bookshelf) is marked so unless its rays score it
    ``HALF_TURN_TIE`` explained points above its half turn (:meth:`_Run._half_turn_tied`:
    seen side-on, front and back look alike). With no support (or ``upright=False``)
    a detection's turns about its own z axis are ray-cast instead; it is turned to
    the best when that leads its own clearly and settled when its turn leads every
    turn ``SETTLED_APART`` degrees or more away (:meth:`_Run._settle_alone`).

Deterministic: every random choice comes from ``numpy.random.default_rng(seed)``, drawn
once at the start: the support search's seed, and a random *priority* per scan point.
A subsample of ``k`` of a set of points is the ``k`` of them with the lowest priorities
(:meth:`_Run._subsample`): a uniform random subsample that depends only on the set,
not on what the run drew before, so a change to one cluster's or one stage's work does
not reshuffle the draws of every later one.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import os
import struct
import warnings
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import CsdfError
from ..field import as_field
from ..fit import FitResult, check_fit, fit
from ..fit.lie import rotation_angle
from ..points import sample_spacing
from ..pose import Pose
from ..seeds import rng_arg
from . import modelcache
from .neighbours import (
    along_rays,
    components,
    distinct_points,
    linked_edges,
    neighbourhood,
    normals_arg,
    offset_noise,
    points_arg,
    range_noise,
    sparse_points,
    tangent_frames,
    viewpoint_arg,
    with_copies,
)
from .primitives import PrimitiveDetection, detect_primitives
from .rays import RayIndex
from .surfaces import frame_z

__all__ = ["Detection", "detect", "detections_to_scene", "YAWS", "REFINE_TOP",
           "SUPPORT_SPAN", "SUPPORT_MIN_FRACTION", "MAX_SEE_THROUGH", "MAX_UNEXPLAINED",
           "MAX_MODELS", "YAW_STEPS", "YAW_REFITS", "BAND", "MIN_BAND_FRACTION", "YAW_DOUBT",
           "MAX_INTRUDERS", "RAY_MARGIN", "MAX_FRONT", "MIN_CONFIRMED",
           "SETTLE_STEP", "SETTLED_PLAIN_RAYS", "SETTLED_APART"]

#: upright hypotheses: turns about the support's normal
YAWS = 16
#: hypotheses refined by pose-only steps before the full fit
REFINE_TOP = 3
#: a plane is a support when its points span at least this times the largest model's
#: diameter (at its defaults; for a plane above the first support and parallel to it,
#: which may be a model's top, at its largest sizes: ``_Model.reach``)
SUPPORT_SPAN = 1.2
#: degrees within which a plane counts as parallel to the first support
SUPPORT_PARALLEL = 15.0
#: planes holding fewer than this fraction of the points are not searched as supports
SUPPORT_MIN_FRACTION = 0.05
#: largest fraction of a detection's visible surface where the sensor saw through it
MAX_SEE_THROUGH = 0.12
#: largest fraction of a detection's visible surface see-through or without points
MAX_UNEXPLAINED = 0.25
#: the most models one call searches for
MAX_MODELS = 64
#: a cluster is searched (again) while at least this fraction of it is unclaimed (at
#: 0.3, a bookshelf's 1,334 points left of a 5,731-point cluster it shared with the
#: table in front of it were never searched, fresh scene 920; at 0.2 it is found, and
#: no other output of seeds 720-1019 changed)
CLUSTER_LEFT = 0.2
#: ... and when less is left, each connected piece of what is left with at least this
#: many times ``min_points`` points, not mostly on a detection's surface, is searched
#: on its own (a chair's 730 points left of a 11,900-point cluster it shared with a
#: bookshelf, fresh scene 721); None: never
LEFT_PIECE: float | None = 5.0
#: the least fraction of the free points inside the fitted model's box (its bounds at
#: the fitted parameters, padded by three noise levels) within three noise levels of
#: its surface
MIN_INLIER_FRACTION = 0.75
#: the band around a fitted surface (noise levels) whose free points must mostly lie
#: within three noise levels of it ...
BAND = 5.0
#: ... at least this fraction of them
MIN_BAND_FRACTION = 0.9
#: another cluster joins a fit when at least this fraction of it lies inside the placed
#: model's bounding sphere
PIECE_INSIDE = 0.5
#: a cluster may span this times a model's diameter (its parameters may grow it)
SIZE_SLACK = 1.6
#: the fraction of a cluster's points farthest from its median left out when its span
#: is measured (outliers linked to it)
SPAN_TRIM = 0.01
#: points of a cluster that score the upright hypotheses
SCREEN_POINTS = 200
#: pairs of pose and parameter set whose model-to-scan term the screen computes at once
#: (:meth:`_Run._screen`)
SCREEN_BATCH = 32
#: mesh resolution of the models' surface samples and extent (tight bounds, centre,
#: radius); None: :func:`csdf.mesh`'s own choice, refined where the grid would lose
#: thin parts. (48 voxels lose a bookshelf's back panel and a lamp's spokes; the
#: screen, the yaw scans and the tests were tuned on these samples, and the finer ones
#: lost 6 objects of 797 on seeds 0-199: only the turn profile takes the finer ones,
#: :attr:`_Model.fine`)
MODEL_RESOLUTION: int | None = 48
#: mesh resolution of a model at its largest parameters (:func:`_reach`)
REACH_RESOLUTION = 24
#: surface samples per model for the screen's model-to-scan term
SURFACE_SAMPLES = 300
#: weight of the model-to-scan term of the screening cost
BACK_WEIGHT = 4.0
#: parameter sets besides the defaults that the hypotheses are screened with: those of
#: ``PARAM_BANK`` draws whose height is nearest the cluster's
PARAM_STARTS = 4
#: parameter draws per model (a Latin hypercube over its declared ranges)
PARAM_BANK = 32
#: the draws leave this fraction of each range out at both ends
BANK_MARGIN = 0.1
#: columns (per side) and levels of the probe of each draw's height, and the reach of
#: the levels (times the model's height at the defaults)
HEIGHT_COLUMNS = 7
HEIGHT_LEVELS = 128
HEIGHT_REACH = 2.5
#: models refined per cluster: those whose best upright hypothesis costs least
MODELS_REFINED = 3
#: ... of which those whose screening cost is at most this times the best model's
SCREEN_RATIO = 2.0
#: a fit whose up axis is within this many degrees of the support's normal is stood
#: upright on the support; one tilted more is rejected (``upright=True``)
UPRIGHT_SNAP = 15.0
#: a cluster reaching farther than this times a model's footprint radius from its
#: centroid also gets hypotheses at the centres of k-means groups of its footprint
FEET_REACH = 1.2
#: the most k-means groups tried (k = 2 .. FEET_SPLIT)
FEET_SPLIT = 3
#: the most failed models (ranked above the winner by the screen) whose placements
#: are turned
TURN_MODELS = 2
#: points of the final fit at most (a seeded subsample)
FIT_POINTS = 1200
#: yaws (turns about the support's normal) at which a fit's explained mass is scanned
YAW_STEPS = 72
#: the scan's best yaws (local maxima, away from the fit's own) fitted again
YAW_REFITS = 1
#: ... and for a failed model's placement
YAW_REFITS_FAILED = 1
#: a scanned yaw within this many degrees of the fit's own is the fit's own
YAW_SAME = 15.0
#: points that score a yaw scan at most (a seeded subsample)
SCAN_POINTS = 1500
#: the explained mass of a point saturates at this many noise levels from the surface
GAIN_CAP = 3.0
#: rays whose scan point lies beyond the fitted model's bounding sphere (free space
#: behind it) that score its turns, at most (a seeded subsample); the rays of the
#: points within the sphere score up to RAY_INSIDE (a lamp's spokes are a few dozen of
#: them: a subsample of all the rays loses them)
RAY_BACKGROUND = 1000
#: rays of the points within the sphere that score its turns, at most (a seeded
#: subsample: a bookshelf seen whole has 10,000; a lamp 500-2,500)
RAY_INSIDE = 4000
#: step of the turns the winner is ray-cast at (degrees)
RAY_STEP = 5.0
#: a ray-cast turn replaces the winner's own when it scores this many explained points'
#: worth (``GAIN_CAP_LOG`` each) more
RAY_MARGIN = 2.0
#: other parameter starts a fit that failed verification is fitted again from
RETRY_STARTS = 2
#: ... when it explained at least this fraction of the free points it was fitted to
RETRY_EXPLAINED = 0.5
#: a winner whose visible surface is unexplained over this fraction (the sensor saw
#: through it or nothing there) is fitted again from ``RETRY_STARTS`` other parameter
#: starts too
REFIT_UNEXPLAINED = 0.05
#: the largest fraction of the points inside a fit's box that may lie in its free
#: space in front of it (:meth:`_Run._intruders`)
MAX_INTRUDERS = 0.25
#: the largest fraction of the rays on a fit's visible surface that may show a point
#: of its own clusters floating in front of it (:meth:`_Run._front_fraction`)
MAX_FRONT = 0.1
#: rays cast for that test at most (an even stride over them)
FRONT_RAYS = 6000
#: the least fraction of the sensor's rays on a detection's silhouette (through its
#: bounding sphere, hitting it) whose range the model explains (:meth:`_Run._ray_evidence`;
#: the rest seen through it or hidden behind nearer points): right detections on seeds
#: 0-39 have 36 % or more, a bookshelf fitted over a hidden table 6 %
MIN_CONFIRMED = 0.2
#: the turned winner's refit: free points of its clusters within this many noise levels
#: of its surface, at most ``POLISH_POINTS`` of them (a seeded subsample), and its
#: residual evaluations
POLISH_BAND = 5.0
POLISH_POINTS = 1200
POLISH_ITER = 60
#: the refit's rounds at most: each after the first gathers its band again about the last
#: round's surface, while that adds more than ``POLISH_GROWN`` of the last band's points
#: (a lamp whose winner had its shade 8 cm short kept it 4 cm short in one round: the
#: shade's upper points lay outside the first band)
POLISH_ROUNDS = 3
POLISH_GROWN = 0.02
#: upright refits from a better-scoring turn of the winner's upright refit (0: the turn
#: is judged at the refit's own parameters only)
TURN_REFITS = 0
#: ... and the margin (explained points) by which a turn at those parameters must
#: score more than the refit's own turn
TURN_RAY_MARGIN = 1.0
#: a winner that :meth:`_Run._resolve_yaw` keeps as it was fitted (no refit replaced
#: it) is turned about its axis too, at its own parameters, when its rays score a turn
#: ``TURN_RAY_MARGIN`` better (the turns were judged across two sets of parameters
#: before). Over the benchmark's 300 seeds: 9 lamps turned right, 2 turned wrong
#: (1097 -> 1104 objects, 75 -> 68 false positives)
ORIG_TURNS = True
#: the turn scan's rays are bundles of five parallel rays this many noise levels apart
#: (:meth:`_Run._ray_scores`' ``spread``): a small part fitted a few millimetres off
#: (a lamp's 5 mm spokes, placed by shade parameters fitted to points at 11-23 mm
#: noise) still meets the rays that saw it
RAY_SPREAD = 0.2
#: the last step of a detection whose turn is in doubt (:meth:`_Run.settle_turn`):
#: its turns this many degrees apart over one period of its symmetry are ray-cast
#: without the spread, and it takes the best. A lamp's turn scores peak within about
#: 3 degrees (a 5 mm spoke 10 cm out), so at 5-degree steps the peak fell between two
#: turns: over seeds 720-1019, at the 244 lamp detections' own parameters, the best
#: of 1-degree steps lay within 17 degrees of the true turn for 204, of 2-degree
#: steps 203, of 5-degree steps 190
SETTLE_STEP = 2.0
#: ... its parameters are first refitted to its rays at the best of those turns: the
#: plain rays' score maximised by SciPy's Nelder-Mead over every parameter, within its
#: range, in at most this many evaluations from a simplex ``RAY_REFIT_STEP`` of each
#: range wide (0: no refit), and the turns scanned again at those. A range sensor's
#: noise lies along its rays, so the rays place a shade's rims, seen in outline,
#: closer than the points do: over the same lamps the shade heights came 9.9 -> 2.9
#: mm from the truth (medians), the stems 5.6 -> 2.9 mm, and the best turn was right
#: (MSSD under a tenth of the diameter) for 212 instead of 200
RAY_REFIT_EVALS = 60
RAY_REFIT_STEP = 0.05
#: ... only when the best turn at its own parameters leads every turn
#: ``SETTLED_APART`` degrees or more away by under this many explained points: over
#: the same lamps, the 136 that lead by 2 or more took the same turn either way
RAY_REFIT_BELOW = 2.0
#: ... and its turn is settled when it scores this many explained points more than
#: every turn ``SETTLED_APART`` degrees or more away; otherwise :func:`detect` leaves
#: it out unless asked (``keep_unsettled``). Over the same lamps, 194 right and 4
#: wrong lead by 0.5 or more (0.25: 202 and 14; 1.0: 176 and 1); the rule before
#: (spread rays, points or plain rays at 5-degree steps, no refit) settled 169 right
#: and 31 wrong
SETTLED_PLAIN_RAYS = 0.5
#: ... the turns that compete with a detection's own, in degrees from it: a lamp is
#: lost at about 17 degrees off (MSSD over a tenth of its diameter)
SETTLED_APART = 20.0
#: a detection of a model whose turn is not in doubt but whose half turn about the
#: support's normal is not a symmetry (a bookshelf: open front, closed back) is
#: unsettled unless its plain rays score it more than this many explained points above
#: its half turn (:meth:`_Run._half_turn_tied`; None: never). Seen side-on, a
#: bookshelf's front and back differ by a 6 mm back panel and a kick board set back 2
#: cm, which the scan's noise hides: over seeds 720-1019 the settled bookshelves whose
#: half turn scored within 5 points were 7 right and 7 wrong, over fresh seeds
#: 1020-1119 1 right and 7 wrong. With the rule, 720-1019 found 1,101 -> 1,093 objects
#: with 37 -> 28 false positives, 1020-1119 359 -> 357 with 16 -> 6, and fresh seeds
#: 1120-1219 365 -> 361 with 15 -> 9
HALF_TURN_TIE: float | None = 5.0
#: a winner's turn is in doubt when the model has a turn, not a symmetry, that moves
#: less than this fraction of its surface samples by more than three noise levels
#: (the turn rests on a small part of it: a lamp's spokes)
YAW_DOUBT = 0.03
#: a parameter within this fraction of its range's span of an end is at its bound (a
#: size no point holds, pushed out by the fit: a bookshelf's depth seen from the front)
AT_BOUND = 0.02
#: the fractions of the way from a parameter's bound to its default at which
#: :meth:`_Run._shrunk` holds it
SHRINK_STEPS = (0.5, 1.0)
#: the fractions of a winner's width and depth that :meth:`_Run._narrowed` cuts it
#: back to, from either side (None: not cut); a winner that leaves over
#: ``REFIT_UNEXPLAINED`` of its visible surface unexplained is cut so
NARROW_STEPS: tuple[float, ...] | None = (0.5, 0.7)
#: how many of the best fits of :meth:`_Run._refit_unexplained` are cut back
NARROW_FITS = 2
#: two detections of one model that share over this fraction of either's box (its
#: surface samples inside the other's box) are fitted again as one
#: (:func:`_merge_overlaps`; None: never)
MERGE_OVERLAP: float | None = 0.2
#: the share of the two detections' points that the one fit must explain
MERGE_COVER = 0.9
#: two detections of one model that share no space are fitted again as one from a
#: start that spans both when the model's surface between them is hidden from the
#: sensor (at least this share of it behind nearer points; None: never): the two ends
#: of a table whose middle an object in front hid, each fitted short
MERGE_HIDDEN: float | None = 0.5
#: the fewest of the spanning start's surface samples between the two that decide it
MERGE_HIDDEN_SAMPLES = 10
#: names of the parameters the upright refit adds: the turn about the model's z axis
#: and the shift along its x and y axes
UPRIGHT_PARAMS = ("_upright_yaw", "_upright_dx", "_upright_dy")
#: a free fit from a turned upright start (:meth:`_Run._turns`) that falls over is
#: fitted again held upright, and kept when that explains its points better
#: (:meth:`_Run._candidate`)
HELD_UPRIGHT = True
#: the fit from the screen's placement is stood up too when it falls over (as the turns'
#: refits are, :data:`HELD_UPRIGHT`): a bookshelf seen from behind fell from its own,
#: right placement
STAND_FIRST = True
#: a winner that passes with over ``REFIT_UNEXPLAINED`` of its visible surface
#: unexplained also competes with fits held back from the ends of its ranges
#: (:meth:`_Run._refit_unexplained`)
SHRINK_PASSED = True
#: a fit of a model whose width and depth are two parameters (:func:`_extents`) with
#: one of them at its bound is also refitted a quarter turn either way with the two
#: sizes traded, so that the turned model covers the same footprint
#: (:meth:`_Run._swapped`): seen side-on, a bookshelf's or a table's width and depth
#: are easily taken for each other, and the yaw scan, made at the fit's own sizes,
#: does not see that turn
SWAP_TURNS = True
#: a parameter is a width (a depth) when raising it grows the model's bounds along its
#: x (y) axis by at least this much a unit, and along y (x) by at most
#: ``EXTENT_CROSS`` times that
EXTENT_SLOPE = 0.5
EXTENT_CROSS = 0.05
#: when no model's fit to a cluster passes (not only when the band test rejected a
#: large one), the cluster is also tried in two halves (:meth:`_Run.best_in_parts`): a
#: lamp and a distractor cylinder standing side by side make one cluster, and a lamp
#: fitted to both falls over
PARTS_WHEN_UNFIT = True

#: the winner cut back to its points' footprint (:meth:`_Run._trimmed`) where it
#: reaches past them by over this many noise levels and ``TRIM_FRACTION`` of its extent
TRIM_OVERHANG = 5.0
TRIM_FRACTION = 0.1
#: ... and replaces the winner when its explained mass is over this fraction higher
TRIM_GAIN = 0.03
#: an upright winner turned half round at its own sizes replaces it when the sensor's
#: rays score the turn this many explained rays higher (:meth:`_Run._half_turn`;
#: None: not tried). Over 620 seeds the turns that made a wrong bookshelf right led by
#: 29.5-261; two that made a right one wrong led by 12.2 and 23.7 (fresh scenes 486,
#: 358), under this margin (5 until session 43); one at 158.8 (525) remains
HALF_TURN_MARGIN: float | None = 25.0
#: a cluster that no model standing on the support explains, whose lowest points lie
#: over ``LIFT_MIN`` noise levels above it, is tried again with the models standing on
#: the surfaces facing up under it, the lowest of the ``LIFT_LEVELS`` highest first
#: (:meth:`_Run.best_lifted`): each at least ``LIFT_POINTS`` points within
#: ``LIFT_TILT`` degrees of level
LIFT = True
LIFT_MIN = 10.0
LIFT_POINTS = 20
LIFT_TILT = 20.0
LIFT_LEVELS = 3
#: without upright hypotheses, each cluster is also fitted joined by its nearest other
#: clusters (:meth:`_Run.best_joined`) that lie within ``JOIN_GAP`` times the largest
#: model's diameter of it; their gaps are measured on subsamples of ``JOIN_POINTS``
#: points
JOIN_CLUSTERS = True
JOIN_GAP = 0.5
JOIN_POINTS = 2000
#: a cluster whose fits failed with another cluster joined to them as a piece of their
#: object is searched again once a later detection claims points of that cluster
#: (:func:`detect`): a stool standing against a lamp was fitted over both and failed;
#: the lamp, found next, claimed its points, and the stool alone was found
RETRY_JOINED = True

#: a fit gathers its own clusters' points in the bounding sphere of the model at the
#: defaults stretched up to its top at the start's parameters (:meth:`_Run._gather`)
GATHER_SIZED = True
#: a fit that failed verification after taking another cluster's points as a piece of
#: its object is fitted again from the same start on its own clusters' points alone
#: (:meth:`_Run.best_for`): a bookshelf whose sphere took in the clusters of a chair,
#: a lamp and a distractor beside it grew 0.35-0.39 m wider and was seen through, and a
#: quarter-turned fit won instead (benchmark scene 292)
OWN_REFIT = True

#: the verified fits in another pose whose explained mass lies within this fraction of
#: the winner's are cut back and held back from their bounds too, and compete with it
#: (:meth:`_Run._trim_rivals`; None: not done)
TRIM_RIVALS: float | None = 0.05
#: a fit with more than this many parameters at an end of their range
#: (:func:`_at_bound`) fails verification (None: never): something else squeezed
#: into the model: a box 0.27 m high seen at 2.8 cm noise, its lower third taken for
#: the floor, was fitted as a lamp with four of its six sizes at their ends; of 1,019
#: right detections over the benchmark's 280 seeds two had three there, none more
MAX_AT_BOUND: int | None = 3

#: a turn of the winner (:meth:`_Run._turns`) whose refit fails verification with a
#: parameter at an end of its range is held back to its default (:meth:`_Run._shrunk`,
#: the last of ``SHRINK_STEPS``): a bookshelf seen side-on, refitted the right way
#: round, grew its depth to the bound and was seen through, and its wrong half turn won
SHRINK_TURNS = True
#: a detection whose model turned a quarter turn about its z axis with two of its
#: parameters exchanged is the same surface (a table's length and width) is reported
#: in the form whose two values lie nearer their defaults (:func:`_canonical`): a
#: table 1.2 m by 0.94 m came out as 0.94 m long and 1.2 m wide, turned a quarter,
#: the same table but not the length along its x axis that the model's author meant
CANONICAL_SWAP = True
#: a winner narrower or shallower than its model's defaults is grown to them on the
#: side the sensor did not see (:meth:`_Run._completed`) when the grown fit passes
#: every test and explains at most this fraction less than it: a table whose far
#: half an occluder hid was fitted as its near half, 0.7 m short (its moved far legs
#: had explained 1.2 % more, a few points of noise; a narrow bookshelf grown 0.23 m,
#: 3.8 % more). Over the benchmark's 260 seeds 0.01 lost an object, 0.04 gained one
#: over 0.02, and 0.08 lost one and added a false positive
COMPLETE_LOSS = 0.04
#: ... also in the form with exchanged parameters (:func:`_swaps`), so that the
#: hidden side can be the length: a table whose near half showed 0.9 m by 1.0 m had
#: been fitted as a whole table turned a quarter
COMPLETE_SWAPPED = True
#: ... and unless over this fraction, and at least ``COMPLETE_THROUGH_RAYS``, of the
#: sensor's rays that meet its grown part first see through it
#: (:meth:`_Run._seen_through_grown`; None: not asked)
COMPLETE_THROUGH: float | None = 0.5
COMPLETE_THROUGH_RAYS = 20

#: verified fits of a cluster whose explained mass lies within this fraction of the
#: best's are a tie that the sensor's rays break (:meth:`_Run._ray_tie`): a bookshelf
#: seen nearly side-on explains its points as well turned a half turn (front and back
#: swapped), 0.4-0.8 % apart in explained mass, but its open front or its back panel,
#: seen at a grazing angle, tells the two apart along the rays
RAY_TIE = 0.02


@dataclass
class Detection:
    """One known object found in a scan.

    Attributes:
        model: the model's name (the zoo name, the file's stem, or the key it was given
            under).
        pose: the rigid model-to-scan :class:`csdf.Pose`.
        params: the model's parameter values (all of them; estimated by the fit).
        score: the fraction of the model's visible surface that the scan confirms
            (``1 - visible_unexplained`` from the viewpoint; without a viewpoint the
            fraction of the fitted points within three noise levels).
        inliers: ``(K,)`` indices of the scan points it explains (within three noise
            levels of its surface, off the support): those of its own clusters, of
            clusters it explains at least half of, and of no cluster.
        shape: the model (a :class:`csdf.Shape` or :class:`csdf.Program`).
        source: what :func:`detections_to_scene` hands to :meth:`csdf.Scene.add`: the
            zoo name or model file given, else the shape.
        fit: the :class:`csdf.FitResult` of the refinement (its ``quality`` holds the
            verification's figures).
        settled: False when the scan does not settle the model's turn about the
            support's normal (without a support, about its own z axis): the turn
            rests on a small part (a lamp's spokes) and the sensor's rays do not
            prefer it by ``SETTLED_PLAIN_RAYS`` explained
            points to every turn ``SETTLED_APART`` degrees or more away, or the
            model's front and back differ (a bookshelf) and its rays do not score it
            ``HALF_TURN_TIE`` points above its half turn (seen side-on). The pose is
            then a guess between turns (the object and its other parameters are
            found). :func:`detect` returns such detections only with
            ``keep_unsettled=True``.
    """

    model: str
    pose: Pose
    params: dict[str, float]
    score: float
    inliers: np.ndarray
    shape: Any = field(repr=False, default=None)
    source: Any = field(repr=False, default=None)
    fit: FitResult | None = field(repr=False, default=None)
    settled: bool = True

    def __repr__(self) -> str:
        t = np.round(self.pose.translation, 3).tolist()
        return (f"Detection({self.model!r}, at {t}, score={self.score:.2f}, "
                f"{len(self.inliers)} points{'' if self.settled else ', turn unsettled'})")

    def to_dict(self) -> dict:
        """JSON-ready: model, pose matrix, params, score, inlier count, settled."""
        return {"model": self.model, "pose": self.pose.matrix.tolist(),
                "params": {k: float(v) for k, v in self.params.items()},
                "score": float(self.score), "points": int(len(self.inliers)),
                "settled": bool(self.settled)}


@dataclass
class _Model:
    name: str
    shape: Any
    source: Any
    bounds: np.ndarray  # (2, 3) of the surface at the defaults (mesh vertices)
    centre: np.ndarray
    radius: float
    fld: Any
    backend: str
    surface: np.ndarray  # (K, 3) surface samples at the defaults (model frame)
    normals: np.ndarray  # (K, 3) their outward unit normals
    starts: list  # parameter sets the hypotheses start from (None: the defaults)
    foot: float  # radius of the footprint (model xy) about the centre, at the defaults
    heights: np.ndarray  # (S,) the model's top (model z) at each of ``starts``
    reach: float  # its radius at the defaults or at every ranged parameter near its top
    upright_shape: Any = None  # built by _Run._upright_shape (False: not possible)
    #: (K, 3) surface samples at the defaults from the thin-part-refined mesh (model
    #: frame), made on first use (:meth:`_Run._turn_profile`)
    fine: np.ndarray | None = None
    #: the bounds' extents at parameter values (see _span_at), filled on first use
    spans: dict = field(default_factory=dict)
    #: the model's exchangeable pairs (see _swaps), found on first use
    swaps: list | None = None
    #: the name of its entry in the disk cache (:mod:`.modelcache`; None: not kept)
    key: str | None = None
    #: which parts filled on first use the kept entry holds (:func:`_filled`)
    kept: tuple = ()


def _prep_settings() -> tuple:
    """The settings a prepared model depends on (part of its disk cache key)."""
    return ("detect-model-1", MODEL_RESOLUTION, SURFACE_SAMPLES, PARAM_BANK, BANK_MARGIN,
            HEIGHT_COLUMNS, HEIGHT_LEVELS, HEIGHT_REACH)


def _filled(m: _Model) -> tuple:
    """Which of ``m``'s parts made on first use are there: ``(fine, how many spans,
    swaps)``."""
    return (m.fine is not None, len(m.spans), m.swaps is not None)


def _keep(m: _Model) -> None:
    """Write ``m``'s prepared data, with the parts made on first use so far, to its disk
    cache entry (:mod:`.modelcache`)."""
    if m.key is None:
        return
    arrays = {"bounds": m.bounds, "centre": m.centre, "surface": m.surface,
              "normals": m.normals, "heights": m.heights}
    if m.fine is not None:
        arrays["fine"] = m.fine
    meta = {"radius": float(m.radius), "foot": float(m.foot), "reach": float(m.reach),
            "starts": [None if s is None else {k: float(v) for k, v in s.items()}
                       for s in m.starts],
            "spans": [[n, float(v), None if e is None else [float(x) for x in e]]
                      for (n, v), e in m.spans.items()],
            "swaps": None if m.swaps is None else [[a, b, float(t)] for a, b, t in m.swaps]}
    modelcache.store(m.key, arrays, meta)
    m.kept = _filled(m)


def _cache_key(prog: Any) -> str | None:
    """The disk cache entry of a model's program (:mod:`.modelcache`; its bytecode holds
    everything it computes, mesh data included), or None when the program cannot be
    written as bytecode."""
    try:
        return modelcache.entry_key(prog.to_bytes(), _prep_settings())
    except (ValueError, OverflowError, struct.error):
        return None


def _kept_model(name: str, shape: Any, source: Any, fld: Any, key: str) -> _Model | None:
    """The model prepared from its disk cache entry ``key``, or None (none, or one that
    does not hold what a prepared model needs)."""
    hit = modelcache.load(key)
    if hit is None:
        return None
    a, meta = hit
    try:
        m = _Model(name, shape, source, a["bounds"], a["centre"], float(meta["radius"]), fld,
                   fld.backend, a["surface"], a["normals"],
                   [None if s is None else {str(k): float(v) for k, v in s.items()}
                    for s in meta["starts"]],
                   float(meta["foot"]), a["heights"], float(meta["reach"]),
                   fine=a.get("fine"),
                   spans={(str(n), float(v)): None if e is None else np.asarray(e, float)
                          for n, v, e in meta["spans"]},
                   swaps=None if meta["swaps"] is None else [
                       (str(x), str(y), float(t)) for x, y, t in meta["swaps"]],
                   key=key)
    except (KeyError, TypeError, ValueError, AttributeError):
        return None
    if (m.bounds.shape != (2, 3) or m.centre.shape != (3,) or m.surface.ndim != 2
            or m.surface.shape != m.normals.shape or len(m.heights) != len(m.starts)):
        return None
    m.kept = _filled(m)
    return m


def _model(name: str, shape: Any, source: Any) -> _Model:
    from ..metrics import farthest_points, model_points

    try:
        fld = as_field(shape, what="detect")  # the sweep backend: compiled once per model
        key = _cache_key(fld.program)
        kept = None if key is None else _kept_model(name, shape, source, fld, key)
        if kept is not None:
            return kept
        b = fld.bounds
    except CsdfError:
        raise CsdfError(f"detect: model {name!r} has no finite bounds (an unbounded or "
                        f"empty shape); detect looks for bounded objects") from None
    if b is None or not np.all(np.isfinite(b)):
        raise CsdfError(f"detect: model {name!r} has no finite bounds")
    v = model_points(fld, resolution=MODEL_RESOLUTION)
    b = np.array([v.min(axis=0), v.max(axis=0)])
    c = 0.5 * (b[0] + b[1])
    surf = v[farthest_points(v, SURFACE_SAMPLES)]
    g = np.asarray(fld.gradient(surf), dtype=float)
    g /= np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-300)
    # the defaults, and a seeded stratified draw (a Latin hypercube) over the middle of
    # the declared ranges, each with the model's height
    rng = np.random.default_rng(0)
    starts: list = [None]
    ranged = [p for p in fld.program.params if math.isfinite(p.lo) and math.isfinite(p.hi)]
    if ranged:
        strata = np.array([rng.permutation(PARAM_BANK) for _ in ranged])  # (P, B)
        u = (strata + rng.uniform(size=strata.shape)) / PARAM_BANK
        for k in range(PARAM_BANK):
            starts.append({p.name: float(p.lo + (p.hi - p.lo) * (BANK_MARGIN + (
                1 - 2 * BANK_MARGIN) * u[i, k])) for i, p in enumerate(ranged)})
    heights = _heights(fld, starts, b)
    radius = float(np.linalg.norm(v - c, axis=1).max())
    m = _Model(name, shape, source, b, c, radius, fld, fld.backend, surf, g, starts,
               float(np.linalg.norm(v[:, :2] - c[:2], axis=1).max()), heights,
               max(radius, _reach(fld, ranged)), key=key)
    _keep(m)
    return m


def _span_at(m: _Model, p: Any, value: float) -> np.ndarray | None:
    """``(3,)`` the extent of the interval bounds of ``m`` along its axes with its
    parameter ``p`` (one of its program's ``params``) at ``value`` and the others at
    their defaults (None: no bounds there); kept on ``m`` (each costs a bounds search,
    but the defaults' bounds are ``m``'s own)."""
    key = (p.name, value)
    if key not in m.spans:
        b = m.fld.bounds if value == float(p.default) else m.fld.replace(
            params={p.name: value}, check_ranges=False).bounds
        m.spans[key] = None if b is None else np.diff(np.asarray(b, dtype=float),
                                                       axis=0)[0]
    return m.spans[key]


def _growth(m: _Model, name: str, screen: bool = False) -> np.ndarray:
    """``(3,)`` how fast the bounds of ``m`` grow along the model's x, y and z axes as
    its parameter ``name`` rises (bounds per parameter unit, from the bounds with
    ``name`` at the two ends of its range, the others at their defaults; zeros for a
    parameter without a finite range). With ``screen``, from its default to its upper
    end: one bounds search less, good to a few per cent.

    The bounds are found to a few millimetres, so the step is the whole range: over a
    tenth of it (8 cm of a bookshelf's width, 2.5 cm of its depth) their error made
    the width grow 1.19 and the depth 1.53 a unit, and a bookshelf grown to its
    default width without a refit (:meth:`_Run._completed`) moved the one side panel
    the sensor saw by 2 cm."""
    p = next(q for q in m.fld.program.params if q.name == name)
    lo, hi = (float(p.default) if screen else float(p.lo)), float(p.hi)
    if not (math.isfinite(hi - lo) and hi > lo):
        return np.zeros(3)
    a, b = _span_at(m, p, lo), _span_at(m, p, hi)
    return np.zeros(3) if a is None or b is None else (b - a) / (hi - lo)


def _extents(m: _Model, names: Iterable[str] | None = None
             ) -> tuple[str, str, float, float] | None:
    """``(x name, y name, x slope, y slope)``: the parameters of ``m`` that set its
    width (its extent along the model's x axis) and depth (along y), each the one whose
    rise grows the bounds along that axis the most (at least ``EXTENT_SLOPE`` a unit,
    :func:`_growth`) and along the other axis at most ``EXTENT_CROSS`` times as much,
    with those growths; None when the model has no such pair (a stool's seat radius
    widens it both ways), or when ``names`` is given and none of them is the width or
    the depth (looked at first: each parameter's growth costs one or two bounds
    searches)."""
    def axis(n: str) -> int | None:
        g = _growth(m, n, screen=True)
        if max(g[0], g[1]) < 0.5 * EXTENT_SLOPE:
            return None  # (no width or depth: spared the second search)
        g = _growth(m, n)
        for a in (0, 1):
            if g[a] >= EXTENT_SLOPE and abs(g[1 - a]) <= EXTENT_CROSS * g[a]:
                return a
        return None

    if names is not None and all(axis(n) is None for n in names):
        return None
    best: list = [None, None]
    for p in m.fld.program.params:
        a = axis(p.name)
        if a is None:
            continue
        g = float(_growth(m, p.name)[a])
        if best[a] is None or g > best[a][1]:
            best[a] = (p.name, g)
    if best[0] is None or best[1] is None or best[0][0] == best[1][0]:
        return None
    return best[0][0], best[1][0], best[0][1], best[1][1]


def _moved_surface(fld: Any, surf: np.ndarray, params: dict
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The surface samples ``surf`` ``(K, 3)`` of ``fld`` at its defaults moved onto the
    model at ``params`` (one projection step along the gradient; model frame), and
    their unit normals ``(K, 3)`` there."""
    f = fld.replace(params=params, check_ranges=False)
    g = np.asarray(f.gradient(surf), dtype=float)
    moved = surf - np.asarray(f.value(surf), dtype=float)[:, None] * g
    g = np.asarray(f.gradient(moved), dtype=float)
    g /= np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-300)
    return moved, g


def _yaw_matrix(nrm: np.ndarray, th: float) -> np.ndarray:
    """``(3, 3)`` the rotation by ``th`` radians about the unit axis ``nrm`` ``(3,)``
    (Rodrigues' formula)."""
    X = np.array([[0.0, -nrm[2], nrm[1]], [nrm[2], 0.0, -nrm[0]], [-nrm[1], nrm[0], 0.0]])
    return math.cos(th) * np.eye(3) + math.sin(th) * X + (1 - math.cos(th)) * np.outer(
        nrm, nrm)


def _reach(fld: Any, ranged: list) -> float:
    """The radius (about the centre of its bounds, model units) of the model with every
    parameter of ``ranged`` (those with finite ranges) at the top of the middle of its
    range that the parameter bank covers (``1 - BANK_MARGIN`` of the way up): how large
    the model's sizes can make it (a 2.24 m table's top spans 2.5 m, over twice its
    default radius); 0 without ranged parameters or when that model cannot be
    meshed."""
    from ..metrics import model_points

    if not ranged:
        return 0.0
    pv = {p.name: float(p.lo + (1.0 - BANK_MARGIN) * (p.hi - p.lo)) for p in ranged}
    try:
        v = model_points(fld, params=pv, resolution=REACH_RESOLUTION, check_ranges=False)
    except CsdfError:
        return 0.0
    c = 0.5 * (v.min(axis=0) + v.max(axis=0))
    return float(np.linalg.norm(v - c, axis=1).max())


def _heights(fld: Any, starts: list, b: np.ndarray) -> np.ndarray:
    """``(S,)`` the top (largest model z, model units) of the model at each parameter
    set of ``starts`` (None: the defaults), from ``b`` ``(2, 3)``, its bounds at the
    defaults: the highest point within half a column spacing of the surface on
    ``HEIGHT_COLUMNS`` x ``HEIGHT_COLUMNS`` vertical columns over its footprint at the
    defaults, ``HEIGHT_LEVELS`` levels up to ``HEIGHT_REACH`` times its default
    height, less that tolerance."""
    lo, hi = b[0], b[1]
    xs = np.linspace(lo[0], hi[0], HEIGHT_COLUMNS)
    ys = np.linspace(lo[1], hi[1], HEIGHT_COLUMNS)
    tol = 0.5 * max(xs[1] - xs[0], ys[1] - ys[0])
    zs = np.linspace(lo[2], lo[2] + HEIGHT_REACH * (hi[2] - lo[2]), HEIGHT_LEVELS)
    X, Y, Z = np.meshgrid(xs, ys, zs, indexing="ij")
    grid = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
    out = np.empty(len(starts))
    for k, pv in enumerate(starts):
        f = fld if pv is None else fld.replace(params=pv, check_ranges=False)
        near = np.asarray(f.value(grid), dtype=float) <= tol
        out[k] = (grid[near, 2].max() - tol) if near.any() else hi[2]
    return out


def _load(spec: Any, what: str) -> tuple[str, Any, Any]:
    """``(name, shape, source)`` of one model given as a shape, a program, a zoo name or
    a model file."""
    from ..compiler.program import Program
    from ..shapes.base import Shape

    if isinstance(spec, (Shape, Program)):
        return what, spec, spec
    if isinstance(spec, os.PathLike) or (isinstance(spec, str) and (
            os.sep in spec or "/" in spec or Path(spec).suffix)):
        from ..io.model import load_model

        return Path(spec).stem, load_model(Path(spec)), str(spec)
    if isinstance(spec, str):
        from .. import zoo

        return spec, zoo.load(spec), spec
    raise CsdfError(f"detect: {what} must be a shape, a program, a zoo name or a model "
                    f"file; got {type(spec).__name__}")


def _models_arg(models: Any) -> list[_Model]:
    if isinstance(models, str):
        models = [m.strip() for m in models.split(",") if m.strip()]
    if isinstance(models, dict):
        items = [(str(k), *_load(v, str(k))[1:]) for k, v in models.items()]
    else:
        try:
            seq = list(models)
        except TypeError:
            seq = [models]
        items = []
        for i, m in enumerate(seq):
            items.append(_load(m, f"model_{i}"))
    if not items:
        raise CsdfError("detect: no models given")
    if len(items) > MAX_MODELS:
        raise CsdfError(f"detect: {len(items)} models is more than the limit of {MAX_MODELS}")
    names = [n for n, _, _ in items]
    dup = next((n for n in names if names.count(n) > 1), None)
    if dup is not None:
        raise CsdfError(f"detect: model name {dup!r} is given twice")
    return [_cached_model(n, s, src) for n, s, src in items]


#: prepared models kept between calls (:func:`_cached_model`), at most this many
MODEL_CACHE = 32
_MODELS: dict[tuple, tuple[Any, Any, _Model]] = {}


def _cached_model(name: str, shape: Any, source: Any) -> _Model:
    """:func:`_model` of ``(name, shape, source)``, prepared once per process for the
    same shape object (the zoo hands out one shape per name) under the same name and
    source: meshing a model, drawing its parameter bank and probing the bank's heights
    took about half a second a call for the five furniture models, a tenth of a
    scene's time. The entry holds the shape and source, so their ids stay theirs; the
    oldest entry goes when ``MODEL_CACHE`` are held. A model file is read anew each
    call (a new shape); :func:`_model` then reads what was prepared for the same
    bytecode from disk (:mod:`.modelcache`), as it does in a new process."""
    key = (id(shape), name, source if isinstance(source, str) else id(source))
    hit = _MODELS.get(key)
    if hit is not None and hit[0] is shape and hit[1] is source:
        return hit[2]
    m = _model(name, shape, source)
    if len(_MODELS) >= MODEL_CACHE:
        _MODELS.pop(next(iter(_MODELS)))
    _MODELS[key] = (shape, source, m)
    return m


def _feet(F: np.ndarray, foot: float) -> list[np.ndarray]:
    """Where a model of footprint radius ``foot`` may stand among the points ``F``
    ``(N, 3)`` (a cluster dropped onto the support plane): the centroid, and when the
    cluster reaches farther than ``foot`` from it (two objects touching, an object and
    clutter) also the centres of ``k = 2 .. FEET_SPLIT`` k-means groups (deterministic:
    farthest-point starts, a few Lloyd steps)."""
    c0 = F.mean(axis=0)
    feet = [c0]
    if len(F) < 2 or float(np.linalg.norm(F - c0, axis=1).max()) <= FEET_REACH * foot:
        return feet
    for k in range(2, FEET_SPLIT + 1):
        centres = [F[int(np.argmax(np.linalg.norm(F - c0, axis=1)))]]
        for _ in range(1, k):
            d = np.min([np.linalg.norm(F - c, axis=1) for c in centres], axis=0)
            centres.append(F[int(np.argmax(d))])
        C = np.array(centres)
        for _ in range(8):
            lab = np.argmin(((F[:, None, :] - C[None]) ** 2).sum(axis=2), axis=1)
            C = np.array([F[lab == j].mean(axis=0) if (lab == j).any() else C[j]
                          for j in range(k)])
        feet += list(C)
    return feet


def _widest_piece(uv: np.ndarray) -> float:
    """The largest extent along either axis of a connected piece of the points ``uv``
    ``(K, 2)`` (a plane's inliers in its own frame, scene units): points closer than
    four times the 90th percentile of their nearest-neighbour distances are linked,
    so the gaps of the scan's spacing do not split a surface but a gap between two
    surfaces does."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    if len(uv) < 3:
        return float(np.max(np.ptp(uv, axis=0))) if len(uv) else 0.0
    tree = cKDTree(uv)
    dd, _ = tree.query(uv, k=2)
    link = 4.0 * float(np.percentile(dd[:, 1], 90))
    pairs = tree.query_pairs(link, output_type="ndarray")
    g = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                   shape=(len(uv), len(uv)))
    _, lab = connected_components(g, directed=False)
    lo = np.full((lab.max() + 1, 2), np.inf)
    hi = np.full((lab.max() + 1, 2), -np.inf)
    np.minimum.at(lo, lab, uv)
    np.maximum.at(hi, lab, uv)
    return float(np.max(hi - lo))


def _span(Q: np.ndarray) -> float:
    """The diameter (largest distance between two points, scene units) of the points
    ``Q`` ``(N, 3)`` without the ``SPAN_TRIM`` of them farthest from their median: the
    size of a cluster, whatever its turn (the diagonal of its box along the sensor's
    axes made a long table turned by 30 degrees 3.0 m across instead of 2.5), and a
    few outliers linked to its points (4 of a table's 3,173 made it 0.3 m wider) do
    not make it larger than every model."""
    from scipy.spatial import ConvexHull, QhullError

    if len(Q) < 2:
        return 0.0
    r = np.linalg.norm(Q - np.median(Q, axis=0), axis=1)
    core = Q[r <= np.quantile(r, 1.0 - SPAN_TRIM)]
    try:
        core = core[ConvexHull(core).vertices]
    except (QhullError, ValueError):  # flat or too few points: all of them
        pass
    if len(core) > 2000:  # a bound from above: the diagonal of the box
        return float(np.linalg.norm(core.max(axis=0) - core.min(axis=0)))
    d = np.linalg.norm(core[:, None, :] - core[None, :, :], axis=2)
    return float(d.max())


def _two_means(F: np.ndarray) -> np.ndarray:
    """``(N,)`` labels 0 and 1 of a deterministic 2-means split of the points ``F``
    ``(N, 3)`` (farthest-point starts, a few Lloyd steps; label 0 holds the point
    farthest from the centroid)."""
    c0 = F.mean(axis=0)
    a = F[int(np.argmax(np.linalg.norm(F - c0, axis=1)))]
    C = np.array([a, F[int(np.argmax(np.linalg.norm(F - a, axis=1)))]])
    lab = np.zeros(len(F), dtype=int)
    for _ in range(8):
        lab = np.argmin(((F[:, None, :] - C[None]) ** 2).sum(axis=2), axis=1)
        C = np.array([F[lab == j].mean(axis=0) if (lab == j).any() else C[j]
                      for j in range(2)])
    return lab


def _rz(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def detect(points, models, normals=None, viewpoint=None, max_instances=None, seed=0, *,
           noise=None, min_points=None, upright=True, keep_unsettled=False
           ) -> list[Detection]:
    """Find known models in a cluttered scan: their poses and shape parameters.

    Args:
        points: ``(N, 3)`` scan points (scene units, metres for the zoo; for
            :func:`csdf.scan` clouds the camera frame, so ``viewpoint=(0, 0, 0)``).
        models: the models to look for: zoo names (a list, or one comma-separated
            string ``'chair,table,stool'``), model files, shapes, or a dict ``{name:
            model}``.
        normals: ``(N, 3)`` normals, or None to estimate them (12 nearest neighbours).
        viewpoint: ``(3,)`` sensor position in the points' frame, for a single-view scan:
            fits match points to the visible surface and detections are verified
            against free space (strongly recommended).
        max_instances: stop after this many detections (default: no limit).
        seed: seed of every random choice (an int); equal seeds give equal results.
        noise: the scan's noise standard deviation (scene units); default estimated
            from the support plane's residuals (the median absolute residual of the
            points near it, times 1.4826), or else from the neighbourhoods.
        min_points: the fewest points a detection explains and a cluster holds; default
            ``max(50, N // 500)``.
        upright: with a support plane, hypotheses stand models upright on it (their
            +z along its normal); False searches all rotations (:func:`csdf.fit`'s
            multistart), for objects that may lie on their side.
        keep_unsettled: also return the detections whose turn about the support's
            normal the scan does not settle (:attr:`Detection.settled` False: a
            model whose turn rests on a small part, a lamp's spokes, that neither
            the sensor's rays nor the points about it show clearly). Left out by
            default, as a guessed pose; keep them when the object's presence and
            extent matter more than its turn (a map for collision checks).

    Repeated points (a cloud read off a mesh's triangles, a frame given twice) count
    once: detection runs on the distinct points and each detection's inliers hold
    every copy. Without a viewpoint, up is the side of the largest plane that holds
    most of the points off it.

    Returns:
        :class:`Detection` list in the order found (largest clusters first). An
        unsettled detection left out still claimed its points, so nothing else is
        fitted to them, and counts towards ``max_instances``.

    Warns:
        UserWarning: nothing was found and the cloud is over ``UNIT_RATIO`` times
            larger than every model, or smaller (:func:`unit_hint`: other units?).

    Raises:
        CsdfError: bad points, normals, viewpoint, seed or models, a model without
            bounds.
    """
    P = points_arg(points)
    N = None if normals is None else normals_arg(normals, P)
    rng_arg(seed)  # checked before any work
    ms = _models_arg(models)
    vp = viewpoint_arg(viewpoint)
    if max_instances is not None and (isinstance(max_instances, bool)
                                      or not isinstance(max_instances, (int, np.integer))
                                      or max_instances < 1):
        raise CsdfError(f"max_instances must be None or a whole number >= 1, got "
                        f"{max_instances!r}")
    cap = math.inf if max_instances is None else int(max_instances)
    copies = distinct_points(P)
    if copies is None:
        out = _detect(P, ms, N, vp, cap, seed, noise, min_points, upright)
    else:
        # repeated points: found on the distinct ones, each detection given every copy
        keep, owner = copies
        out = _detect(P[keep], ms, None if N is None else N[keep], vp, cap, seed, noise,
                      min_points, upright)
        for d in out:
            d.inliers = with_copies(d.inliers, owner)
    for m in ms:  # what this call made on first use kept for the next process
        if m.key is not None and _filled(m) != m.kept:
            _keep(m)
    hint = None if out else unit_hint(P, ms)
    if not keep_unsettled:
        out = [d for d in out if d.settled]
    if hint is not None:
        warnings.warn(f"detect found nothing: {hint}", UserWarning, stacklevel=2)
    return out


#: a cloud this many times larger than the largest model (or smaller than the
#: smallest) is taken for one in other units (:func:`unit_hint`)
UNIT_RATIO = 50.0


def unit_hint(points: np.ndarray, models: list[_Model]) -> str | None:
    """Why a cloud ``points`` ``(N, 3)`` may hold none of ``models``: a sentence when its
    extent (the diagonal of its box) is over ``UNIT_RATIO`` times the largest model's
    diameter or under ``1 / UNIT_RATIO`` times the smallest's (a scan in millimetres
    looked at with models in metres), else None."""
    ext = float(np.linalg.norm(np.ptp(points, axis=0))) if len(points) else 0.0
    big = max(2.0 * m.reach for m in models)
    small = min(2.0 * m.radius for m in models)
    if ext > UNIT_RATIO * big:
        return (f"the cloud spans {ext:.4g} units, {ext / big:.0f} times the largest "
                f"model ({big:.3g}); are the points in another unit than the models "
                f"(millimetres against metres: scale them by 0.001)?")
    if 0.0 < ext < small / UNIT_RATIO:
        return (f"the cloud spans {ext:.4g} units, 1/{small / ext:.0f} of the smallest "
                f"model ({small:.3g}); are the points in another unit than the models "
                f"(metres against millimetres: scale them by 1000)?")
    return None


def _detect(P: np.ndarray, ms: list[_Model], normals, vp: np.ndarray | None, cap: float,
            seed, noise, min_points, upright: bool) -> list[Detection]:
    """:func:`detect` on checked, distinct points ``P`` ``(N, 3)``, their checked unit
    ``normals`` ``(N, 3)`` or None, models ``ms``, viewpoint ``vp`` and at most ``cap``
    detections (the other arguments as :func:`detect`'s)."""
    if len(P) < 10:
        return []
    run = _prepare(P, ms, normals, vp, seed, noise, min_points, upright)
    out: list[Detection] = []
    failed = []  # (cluster, the clusters its failed fits joined, their claimed counts)
    for members in run.clusters:
        joined = _search(run, members, out, cap)
        if joined and RETRY_JOINED:
            failed.append((members, joined, _claimed_in(run, joined)))
        if len(out) >= cap:
            break
    # a cluster whose fits failed with a neighbour's points joined (a stool standing
    # against a lamp, fitted over both) is searched again once a later detection has
    # claimed some of those points
    for members, joined, before in failed:
        if len(out) >= cap:
            break
        if any(n > before.get(c, 0) for c, n in _claimed_in(run, joined).items()):
            _search(run, members, out, cap)
    return _merge_overlaps(run, out)


def _merge_overlaps(run: _Run, out: list[Detection]) -> list[Detection]:
    """The detections ``out`` with each pair of one model that share space
    (``MERGE_OVERLAP``) replaced by one fit to both's points, when such a fit passes
    and explains ``MERGE_COVER`` of them (:meth:`_Run.merged`; in the first's place);
    likewise each pair that shares none but whose model, grown to span both, would
    have its surface between them hidden from the sensor (``MERGE_HIDDEN``,
    :meth:`_Run.spanning`), fitted from those spanning starts.

    Two solid objects cannot overlap. A table whose middle a bookshelf in front hid
    was two clusters, and each was found as a short table, the two overlapping
    (benchmark scene 170), or, the hidden part longer, 0.3 m apart (scene 316)."""
    if (MERGE_OVERLAP is None and MERGE_HIDDEN is None) or run.plane is None \
            or not run.upright:
        return out
    out = list(out)
    models = {m.name: m for m in run.models}
    i = 0
    while i < len(out):
        m = models[out[i].model]
        for j in range(i + 1, len(out)):
            if out[j].model != m.name:
                continue
            shared = run.overlap(m, out[i], out[j])
            if MERGE_OVERLAP is not None and shared > MERGE_OVERLAP:
                one = run.merged(m, out[i], out[j])
            elif MERGE_HIDDEN is not None and shared == 0.0 and (
                    spans := run.spanning(m, out[i], out[j])):
                one = run.merged(m, out[i], out[j], spans)
            else:
                continue
            if one is not None:
                one.settled = run.settle_turn(one)
                out[i] = one
                del out[j]
                break
        else:
            i += 1
    return out


def _search(run: _Run, members: np.ndarray, out: list, cap: float) -> set[int]:
    """Finds objects in the cluster ``members`` ``(K,)`` (point indices) until none
    passes or too few of its points are left unclaimed, appending them to ``out``
    (up to ``cap`` in all) and claiming their inliers; returns the other clusters the
    last, failed search's fits joined as pieces of their object (empty when it
    stopped for want of points)."""
    while len(out) < cap:
        free = members[~run.claimed[members]]
        if len(free) < run.mp or len(free) < CLUSTER_LEFT * len(members):
            if LEFT_PIECE is not None:
                for piece in run.left_pieces(free, out):
                    _search(run, piece, out, cap)
            return set()
        run.joined = set()
        det = run.best_for(free)
        if det is None:
            det = run.best_in_parts(free)
        det = run.best_joined(free, det)
        if det is None:
            det = run.best_lifted(free)
        if det is None:
            return set(run.joined)
        det.settled = run.settle_turn(det)
        run.claimed[det.inliers] = True
        out.append(det)
    return set()


def _claimed_in(run: _Run, clusters: set[int]) -> dict[int, int]:
    """How many points of each of ``clusters`` are claimed: ``{cluster: count}``."""
    return {c: int(np.count_nonzero(run.claimed[run.label == c])) for c in clusters}


def _prepare(P: np.ndarray, ms: list[_Model], normals, vp: np.ndarray | None, seed,
             noise, min_points, upright: bool) -> _Run:
    """Steps 1-3 of :func:`detect` on checked points ``P`` ``(N, 3)``, their checked
    unit ``normals`` ``(N, 3)`` (:func:`.neighbours.normals_arg`) or None, models ``ms``
    and viewpoint ``vp`` ``(3,)`` or None (the other arguments as :func:`detect`'s):
    the run's state with its supports and clusters found."""
    n = len(P)
    nb = neighbourhood(P, viewpoint=vp, want_normals=normals is None)
    N = nb.normals if normals is None else normals
    sigma = nb.noise if noise is None else float(noise)
    if not (math.isfinite(sigma) and sigma > 0):
        raise CsdfError(f"noise must be a positive number; got {noise!r}")
    mp = max(50, n // 500) if min_points is None else max(4, int(min_points))
    run = _Run(P, N, nb, vp, sigma, mp, rng_arg(seed), ms)
    run.estimate_noise = noise is None
    run.upright = bool(upright)
    run.find_supports()
    run.find_clusters()
    return run


def _joined(label: np.ndarray, labels: np.ndarray, idx: np.ndarray, total: np.ndarray
            ) -> list[int]:
    """The clusters among ``labels`` ``(K,)`` (points' cluster labels, -1 for none) that
    a fit on the points ``idx`` takes as its object's: those of ``idx`` (by the scan's
    labels ``label`` ``(M,)``), and any other with at least ``PIECE_INSIDE`` of
    ``total[c]`` (its points that count, ``(C,)``) among ``labels`` (a piece of the same
    object cut off by an occluder)."""
    labs, counts = np.unique(labels[labels >= 0], return_counts=True)
    own = set(np.unique(label[idx]).tolist())
    return [int(c) for c, k in zip(labs, counts) if c in own or k >= PIECE_INSIDE * total[c]]


class _Run:
    """The state of one :func:`detect` call."""

    def __init__(self, P, N, nb, vp, sigma, mp, rng, models):
        self.P, self.N, self.nb, self.vp = P, N, nb, vp
        self.sigma, self.mp, self.models = sigma, mp, models
        # every random draw of the run, made here (see the module's notes)
        self.support_seed = int(rng.integers(2**31))
        self.fit_seed = int(rng.integers(2**31))
        self.priority = rng.random(len(P))
        self.support = np.zeros(len(P), dtype=bool)
        self.claimed = np.zeros(len(P), dtype=bool)
        self.plane: tuple[np.ndarray, float] | None = None
        #: the height above the support of the surface the current hypotheses stand on
        #: (:meth:`best_lifted`; 0: the support itself)
        self.lift = 0.0
        self.clusters: list[np.ndarray] = []
        self.label = np.full(len(P), -1)  # cluster of each point (-1: none)
        self.sizes = np.zeros(0, dtype=int)
        self.estimate_noise = True
        self.upright = True
        self.band_rejected = False  # the band test rejected a large fit (best_for)
        #: the other clusters the fits since it was last emptied took as pieces of
        #: their object (:meth:`_gather`)
        self.joined: set[int] = set()
        self.unfit = False  # models were fitted and none passed (best_for)
        self.too_wide = False  # the points span more than any model may (best_for)
        #: (N,) True at the other half's points while best_in_parts fits one half of a
        #: cluster: another object, not the fit's own (the front test)
        self.foreign: np.ndarray | None = None
        #: per model (by id): its turns, symmetries and whether its turn is in doubt
        #: (:meth:`_doubt`)
        self.doubts: dict[int, tuple[np.ndarray, np.ndarray, bool]] = {}
        if vp is not None:
            d = P - vp
            self.dirs = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)

    def find_supports(self) -> None:
        n = len(self.P)
        span_min = SUPPORT_SPAN * 2.0 * max(m.radius for m in self.models)
        planes = detect_primitives(
            self.P, self.N, kinds=("plane",), epsilon=3.0 * self.sigma,
            min_points=max(self.mp, int(SUPPORT_MIN_FRACTION * n)),
            seed=self.support_seed, viewpoint=self.vp, max_primitives=4, reorder=False)
        # a plane above the first support and parallel to it may be a model's top (a
        # 1.94 m table's spans 2.3 m, over the largest default diameter): it is a
        # support only if no model could be that large, piece by piece (two tables of
        # one height side by side are one plane, 3.6 m across in benchmark scene 1004)
        span_top = SUPPORT_SPAN * 2.0 * max(m.reach for m in self.models)
        for pl in planes:
            Q = self.P[pl.inliers]
            nrm = np.asarray(pl.params["normal"])
            R = frame_z(nrm)
            uv = Q @ R[:, :2]
            span = float(np.max(uv.max(axis=0) - uv.min(axis=0)))
            if span < span_min:
                continue
            if self.plane is not None and abs(
                    nrm @ self.plane[0]) >= math.cos(math.radians(SUPPORT_PARALLEL)) and \
                    np.median(Q @ self.plane[0]) - self.plane[1] > 3.0 * self.sigma and \
                    _widest_piece(uv) < span_top:
                continue
            off = float(pl.params["offset"])
            d = self.P @ nrm - off
            if self.plane is None and self.vp is None:
                # no sensor to face: the plane's normal from unoriented normals has
                # either sign, and "up" is the side that holds most of the points off
                # it (what stands on a floor or a table top)
                away = np.abs(d) > 3.0 * self.sigma
                if np.count_nonzero(d[away] < 0.0) > np.count_nonzero(d[away] > 0.0):
                    nrm, off, d = -nrm, -off, -d
            if self.plane is None and self.estimate_noise:
                # the noise level from the support's residuals (the neighbourhoods'
                # estimate is low when the noise is not small against the spacing)
                band = np.abs(d) <= 8.0 * self.sigma
                off += float(np.median(d[band]))
                d = self.P @ nrm - off
                r = np.abs(d[band])
                if self.vp is not None:
                    # a range sensor's noise lies along its rays: a point on a plane
                    # seen at incidence theta is off it by the range error times
                    # cos(theta), and frontal surfaces get the whole range error
                    r = along_rays(r, np.abs(self.dirs[band] @ nrm))
                self.sigma = max(self.sigma, 1.4826 * float(np.median(r)))
            # the plane's slab: its points and every point within three noise levels
            self.support |= np.abs(d) <= 3.0 * self.sigma
            self.support[pl.inliers] = True
            if self.plane is None:  # the largest support: its normal is up
                self.plane = (nrm, off)
        if self.plane is None and self.estimate_noise:
            # no support to read the noise from (an object scanned on its own): each
            # range against its neighbouring rays' (a single view), else each point's
            # offset from its neighbours' plane
            self.sigma = max(self.sigma, range_noise(self.P, self.vp) if self.vp is not None
                             else offset_noise(self.P, self.nb))

    def find_clusters(self) -> None:
        mask = ~self.support & ~sparse_points(self.nb, self.P, self.vp)
        if self.plane is not None:  # below the support is not an object on it
            nrm, off = self.plane
            mask &= self.P @ nrm - off > 0
        lab = components(self.nb, mask, linked_edges(self.nb, strict=True))
        sizes = np.bincount(lab[lab >= 0]) if (lab >= 0).any() else np.zeros(0, int)
        big = sizes >= self.mp
        self.label = np.full(len(lab), -1)
        if len(big):
            self.label = np.where(lab >= 0, np.where(big[np.maximum(lab, 0)], lab, -1), -1)
        self.sizes = sizes
        order = np.argsort(-sizes, kind="stable")
        self.clusters = [np.flatnonzero(lab == i) for i in order if big[i]]

    # -- hypotheses -----------------------------------------------------------------
    def _upright(self, m: _Model, Q: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """Upright poses ``(R, t)`` of model ``m`` on the support near points ``Q``
        (raised by :attr:`lift`)."""
        nrm, off = self._standing()
        Rup = frame_z(nrm)
        poses = []
        for foot in _feet(Q - np.outer(Q @ nrm - off, nrm), m.foot):
            away = None
            if self.vp is not None:
                a = foot - self.vp
                a = a - (a @ nrm) * nrm
                if np.linalg.norm(a) > 0:
                    away = a / np.linalg.norm(a)
            shifts = [np.zeros(3)] + ([away * m.radius / 3.0] if away is not None else [])
            for k in range(YAWS):
                R = Rup @ _rz(2.0 * math.pi * k / YAWS)
                c = R @ m.centre
                for sh in shifts:
                    t = foot + sh - (c - (c @ nrm) * nrm)  # footprint centre over the foot
                    t = t - (t @ nrm - off + m.bounds[0, 2]) * nrm  # lowest point on plane
                    poses.append((R, t))
        return poses

    def _two_sided(self, m: _Model, poses, S: np.ndarray, params: dict | None = None
                   ) -> np.ndarray:
        """``(H,)`` the screening cost of each pose ``(R, t)`` of model ``m``, in units
        of ``fs^2`` (``fs`` the wide residual scale): the mean Huber cost of the model's
        signed distance at the scan points ``S``, plus the mean truncated squared
        distance from the model's surface samples that face the sensor to the nearest
        scan point (a model standing where the sensor saw nothing pays)
        (:meth:`_screen_fwd` plus ``BACK_WEIGHT`` times :meth:`_screen_back`)."""
        fs = self._fs_wide(m)
        back = self._screen_back(m, poses, self._screen_surface(m, params))
        return (self._screen_fwd(m, poses, S, params) + BACK_WEIGHT * back) / fs ** 2

    def _screen_fwd(self, m: _Model, poses, S: np.ndarray, params: dict | None
                    ) -> np.ndarray:
        """``(H,)`` the first term of :meth:`_two_sided` (scene units squared): the
        mean Huber cost of ``m``'s signed distance at ``params`` at the scan points
        ``S`` ``(M, 3)`` for each pose ``(R, t)``; over ``fs^2``, a lower bound of the
        whole cost (the other term is not negative)."""
        fs = self._fs_wide(m)
        fld = m.fld if params is None else m.fld.replace(params=params, check_ranges=False)
        q = np.concatenate([(S - t) @ R for R, t in poses])
        f = np.asarray(fld.value(q), dtype=float).reshape(len(poses), len(S))
        a = np.abs(f)
        return np.where(a <= fs, 0.5 * a * a, fs * (a - 0.5 * fs)).mean(axis=1)

    def _screen_surface(self, m: _Model, params: dict | None
                        ) -> tuple[np.ndarray, np.ndarray]:
        """``m``'s surface samples ``(K, 3)`` and their normals ``(K, 3)`` (model frame)
        for the screen at ``params`` (None: the defaults): the samples moved onto the
        varied model by one step along the gradient, the normals the defaults'."""
        surf, nrm = m.surface, m.normals
        if params is not None:
            fld = m.fld.replace(params=params, check_ranges=False)
            g = np.asarray(fld.gradient(surf), dtype=float)
            surf = surf - np.asarray(fld.value(surf), dtype=float)[:, None] * g
        return surf, nrm

    def _screen_back(self, m: _Model, poses, sn: tuple[np.ndarray, np.ndarray]
                     ) -> np.ndarray:
        """``(H,)`` the second term of :meth:`_two_sided` before its weight (scene units
        squared): for each pose ``(R, t)``, the mean over the surface samples ``sn``
        (:meth:`_screen_surface`) that face the sensor of half the squared distance to
        the nearest scan point, truncated at ``fs``; a sample hidden behind a nearer
        scan point costs nothing. Each pose's value depends on that pose alone."""
        fs = self._fs_wide(m)
        surf, nrm = sn
        X = np.stack([surf @ R.T + t for R, t in poses])  # (H, K, 3)
        if self.vp is not None:
            Nw = np.stack([nrm @ R.T for R, _ in poses])
            front = np.einsum("hki,hki->hk", Nw, self.vp - X) > 0
        else:
            front = np.ones(X.shape[:2], dtype=bool)
        dd = np.zeros(X.shape[:2])  # only the sensor-facing samples are looked up
        Xf = X[front]
        q = np.zeros(len(Xf))
        if self.vp is not None:
            # a sample whose ray shows a scan point nearer than it is hidden (by another
            # object): its missing points are no evidence against the pose (it costs
            # nothing, so only the others are looked up: a third of them in clutter)
            seen = ~self._occluded(Xf, fs)
            rays, _ = self._ray_index()
            q[seen], _ = rays.nearest_point(Xf[seen], self.P, self.vp, fs, self.nb.tree)
        else:
            q[:], _ = self.nb.tree.query(Xf, k=1, distance_upper_bound=fs)
        dd[front] = np.minimum(q, fs)
        return (np.where(front, 0.5 * dd * dd, 0.0).sum(axis=1)
                / np.maximum(front.sum(axis=1), 1))

    def _occluded(self, X: np.ndarray, margin: float) -> np.ndarray:
        """Which of the points ``X`` ``(..., 3)`` the sensor could not see: the scan
        point on the ray through each (the nearest ray within the scan's angular
        spacing) lies nearer the sensor by more than ``margin`` (scene units). Points
        whose ray holds no scan point are not occluded (shape ``X.shape[:-1]``)."""
        rays, rng_scan = self._ray_index()
        v = X - self.vp
        r = np.linalg.norm(v, axis=-1)
        dd, j = rays.nearest((v / np.maximum(r, 1e-300)[..., None]).reshape(-1, 3))
        j = np.minimum(j, len(self.P) - 1).reshape(r.shape)
        return np.isfinite(dd).reshape(r.shape) & (rng_scan[j] < r - margin)

    def _fs_wide(self, m: _Model) -> float:
        return max(3.0 * self.sigma, 0.02 * m.radius)

    def _fs_fit(self, m: _Model) -> float:
        """The residual scale (scene units) of the fits of ``m``'s candidates and
        refits, and of the cost that compares them (:meth:`_cauchy_cost`)."""
        return max(self.sigma, 0.005 * m.radius)

    def _placed(self, m: _Model, idx: np.ndarray, S: np.ndarray
                ) -> tuple[float, FitResult | None]:
        """Step 4 for model ``m``: the best upright hypothesis after pose-only steps,
        and its screening cost (:meth:`_two_sided`)."""
        poses = self._upright(m, self.P[idx])
        nrm, off = self._standing()
        top = float(np.percentile(self.P[idx] @ nrm - off, 99.0))
        # the defaults, and the draws whose height is nearest the cluster's (the top of
        # an object standing on the support is seen from above and rarely occluded)
        order = 1 + np.argsort(np.abs(m.heights[1:] - top), kind="stable")
        sets = [0, *order[:PARAM_STARTS].tolist()]
        cands = self._screen(m, poses, S, sets)
        best: tuple[float, FitResult | None] = (math.inf, None)
        for _, i, k in cands[:REFINE_TOP]:
            R, t = poses[i]
            pv = m.starts[k]
            r = fit(m.shape, S, init={"rotation": R, "translation": t, "params": pv or {}},
                    estimate=("pose",), loss="huber", f_scale=self._fs_wide(m),
                    escape=False, max_iter=15, backend=m.backend, check_ranges=False)
            c = float(self._two_sided(m, [(r.rotation, r.translation)], S, pv)[0])
            if c < best[0]:
                best = (c, r)
        return best

    def _screen(self, m: _Model, poses: list, S: np.ndarray, sets: list[int]) -> list:
        """The ``REFINE_TOP`` best ``(cost, pose index, parameter set)`` of the poses
        ``poses`` of ``m`` at each parameter set ``m.starts[k]`` for ``k`` in ``sets``,
        by :meth:`_two_sided` on the scan points ``S`` (ties by pose index, then set),
        sorted. Exact and cheaper than costing every pair: the first term (the model's
        distances at ``S``) is computed for every pair; it bounds the whole cost from
        below, so the second (``KD-tree`` lookups of the model's surface samples) is
        computed only for the pairs in increasing order of the first, in batches,
        until the next pair's first term exceeds the ``REFINE_TOP``-th best whole cost
        found (on the benchmark's scenes most pairs are never looked up)."""
        fs = self._fs_wide(m)
        fwd = {k: self._screen_fwd(m, poses, S, m.starts[k]) for k in sets}
        queue = sorted((float(fwd[k][i] / fs ** 2), i, k) for k in sets
                       for i in range(len(poses)))
        surfaces: dict[int, tuple] = {}
        done: list[tuple[float, int, int]] = []
        pos = 0
        while pos < len(queue):
            if len(done) >= REFINE_TOP and queue[pos][0] > done[REFINE_TOP - 1][0]:
                break
            batch = queue[pos:pos + SCREEN_BATCH]
            pos += len(batch)
            for k in sorted({b[2] for b in batch}):
                ii = [b[1] for b in batch if b[2] == k]
                if k not in surfaces:
                    surfaces[k] = self._screen_surface(m, m.starts[k])
                back = self._screen_back(m, [poses[i] for i in ii], surfaces[k])
                done += [(float((fwd[k][i] + BACK_WEIGHT * b) / fs ** 2), i, k)
                         for i, b in zip(ii, back)]
            done.sort()
        return done[:REFINE_TOP]

    def _gather(self, m: _Model, idx: np.ndarray, init: FitResult | dict,
                pieces: bool = True) -> np.ndarray:
        """The points a fit of ``m`` placed at ``init`` (a result or a dict of
        ``rotation`` and ``translation``) uses: the free points of the clusters the
        placed model covers: its own (those of ``idx``), and any other that lies mostly
        inside its bounding sphere (a piece of the same object cut off by an occluder),
        not a neighbour that only reaches into it. With ``GATHER_SIZED``, the points of
        its own clusters are taken in that sphere stretched up to the model's top at
        ``init``'s parameters where that is higher (:func:`_heights`; its centre and
        radius grow by half the rise): about the defaults' sphere, the upper fifth of
        a lamp on a stem 0.08 m longer than the default was left out of its fit, whose
        shade came out 0.08 m short and failed the band test. (Stretched for other
        clusters too, a tall bookshelf took its neighbours' pieces: four objects
        lost over the benchmark's 280 seeds.) Without ``pieces``, no other cluster is
        taken (``OWN_REFIT``)."""
        if isinstance(init, dict):
            R, t, pv = init["rotation"], init["translation"], init.get("params")
        else:
            R, t, pv = init.rotation, init.translation, init.params
        R, t = np.asarray(R, dtype=float), np.asarray(t, dtype=float)
        c = R @ m.centre + t
        inside = ~self.claimed & (self.label >= 0) & (
            np.linalg.norm(self.P - c, axis=1) <= 1.1 * m.radius)
        own = np.unique(self.label[idx])
        if pieces:
            keep = _joined(self.label, self.label[inside], idx, self.sizes)
            self.joined.update(set(keep) - set(own.tolist()))
        else:
            keep = own[own >= 0].tolist()
        pts = inside & np.isin(self.label, keep)
        if GATHER_SIZED and pv:
            rise = float(_heights(m.fld, [dict(pv)], m.bounds)[0]) - float(m.heights[0])
            if rise > 0.0:  # its own clusters' points up to its top
                c = R @ (m.centre + np.array([0.0, 0.0, 0.5 * rise])) + t
                pts |= ~self.claimed & (self.label >= 0) & np.isin(self.label, own) & (
                    np.linalg.norm(self.P - c, axis=1) <= 1.1 * (m.radius + 0.5 * rise))
        return np.flatnonzero(pts)

    def _candidate(self, m: _Model, idx: np.ndarray, init: FitResult | dict | None,
                   held: tuple[str, ...] = (), stand: bool = False, pieces: bool = True
                   ) -> FitResult | None:
        """Step 5: the refined fit of model ``m`` to the points ``idx`` from the placed
        hypothesis ``init`` (a result or a dict of ``rotation``, ``translation`` and
        ``params``; None: :func:`csdf.fit`'s multistart search); the parameters named
        in ``held`` stay at their values in ``init``. With ``stand`` (and
        :data:`HELD_UPRIGHT`), a free fit that falls over is fitted again from ``init``
        held upright (:meth:`_polish`), and that is returned when it explains the
        fit's points better than the fallen fit (a lower mean Cauchy cost).
        Without ``pieces``, only the points of its own clusters are gathered
        (:meth:`_gather`)."""
        if init is not None:
            idx = self._gather(m, idx, init, pieces)
        F = self._subsample(idx, FIT_POINTS)
        free = [p.name for p in m.fld.program.params if p.name not in held] \
            if held else None
        try:
            res = fit(m.shape, self.P[F], init=init, estimate=("pose", "params"),
                      params=free,
                      loss="cauchy", f_scale=self._fs_fit(m),
                      viewpoint=self.vp, multistart=init is None,
                      seed=self.fit_seed, max_iter=40, escape=False,
                      debias=False, backend=m.backend, check_ranges=False,
                      check_visible=False)  # judged by _verify
        except CsdfError:
            return None
        if init is None or self.plane is None:
            return res
        out = self._upright_fit(m, F, res, free)
        if out is None and stand and HELD_UPRIGHT and not held:
            # the free fit fell over from an upright start (a bookshelf seen from the
            # back: its flat back panel lets the fit tilt): fitted again from the start
            # with the model held upright on the support
            if isinstance(init, dict):
                R0, t0 = init["rotation"], init["translation"]
                p0 = dict(init.get("params") or {})
            else:
                R0, t0, p0 = init.rotation, init.translation, dict(init.params)
            R0, t0 = self._stood(m, np.asarray(R0, dtype=float), np.asarray(t0, dtype=float))
            p0 = {**dict(res.params), **p0}
            out = self._polish(m, idx, dataclasses.replace(res, rotation=R0, translation=t0,
                                                          scale=1.0, params=p0))
            # kept only when standing explains the points better than the fallen fit
            # does (the fall was the fit's local minimum): a lamp fitted over a ball
            # stands upright no better than it lies (Cauchy costs 0.347 and 0.323,
            # scene 75), a bookshelf seen from the back stands far better (0.41 and
            # 0.83, scene 76)
            if out is not None and self._cauchy_cost(m, out, F) >= self._cauchy_cost(
                    m, res, F):
                out = None
        return out

    def _cauchy_cost(self, m: _Model, res: FitResult, F: np.ndarray) -> float:
        """The mean Cauchy cost (scale: the fit's ``f_scale``) of ``m`` at ``res``'s
        pose and parameters at the points ``F`` ``(K,)`` (indices)."""
        fs = self._fs_fit(m)
        fld = as_field(m.shape, res.params, pose=res.pose, backend=m.backend,
                       what="detect", check_ranges=False)
        d = np.asarray(fld.value(self.P[F]), dtype=float) / fs
        return float(np.mean(np.log1p(d * d)))

    def _stood(self, m: _Model, R: np.ndarray, t: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
        """The pose ``(R (3, 3), t (3,))`` of ``m`` stood upright on the support: its z
        axis along the support's normal, its x axis the old one's projection on the
        support, its floor (the bounds' lowest z) on the plane (raised by
        :attr:`lift`)."""
        nrm, off = self._standing()
        x = R[:, 0] - (R[:, 0] @ nrm) * nrm
        x /= np.linalg.norm(x)
        R = np.stack([x, np.cross(nrm, x), nrm], axis=1)
        t = t - (t @ nrm - off + m.bounds[0, 2]) * nrm
        return R, t

    def _upright_fit(self, m: _Model, F: np.ndarray, res: FitResult,
                     free: list[str] | None = None) -> FitResult | None:
        """``res`` stood on the support (upright, the model's floor on the plane), then
        its parameters (those named in ``free``; None: all) fitted again with that pose
        held. None when ``res`` tilts more than ``UPRIGHT_SNAP`` degrees (it fell over:
        not an object standing on the support)."""
        nrm = self.plane[0]
        if res.rotation[:, 2] @ nrm < math.cos(math.radians(UPRIGHT_SNAP)):
            return None
        R, t = self._stood(m, res.rotation, np.asarray(res.translation, float))
        if free is not None and not free:
            return dataclasses.replace(res, rotation=R, translation=t)
        try:
            return fit(m.shape, self.P[F], init={"rotation": R, "translation": t,
                                                 "params": res.params},
                       estimate=("params",), params=free, loss="cauchy",
                       f_scale=res.quality.get(
                           "noise_level", self.sigma), viewpoint=self.vp, max_iter=30,
                       escape=False, debias=False, backend=m.backend, check_ranges=False,
                       check_visible=False)
        except CsdfError:
            return res

    def _verify(self, m: _Model, res: FitResult
                ) -> tuple[bool, float, np.ndarray, FitResult, float]:
        """Step 6: ``(accepted, score, inliers, checked result, explained mass)``; the
        explained mass (:func:`_gain` of the free points off the support) ranks the
        verified fits of a cluster, whatever points each was fitted to."""
        pose = res.pose
        fld = as_field(m.shape, res.params, pose=pose, backend=m.backend, what="detect",
                       check_ranges=False)
        free = ~self.claimed
        c = pose.apply(m.centre[None])[0]
        near = np.flatnonzero(free & (np.linalg.norm(self.P - c, axis=1)
                                      <= 1.2 * m.radius + 3 * self.sigma))
        d = np.abs(np.asarray(fld.value(self.P[near]), dtype=float))
        close = d <= 3.0 * self.sigma
        inl = near[close & ~self.support[near]]
        off = ~self.support[near]
        gain = float(_gain(d[off], self.sigma).sum())
        # of the free points in a band around the fitted surface, nearly all must lie on
        # it: points a few noise levels off a surface are structure the model does not
        # have there (another object's, or this one's where the fit is wrong)
        # (its own clusters' points: a neighbour standing a few noise levels away is
        # another cluster, and no evidence against the fit)
        if _band_fraction(d, self.label[near], off, self.sigma, self.mp) < MIN_BAND_FRACTION:
            if len(inl) >= 2 * self.mp:
                self.band_rejected = True
            return False, 0.0, inl, res, gain
        ok, score, inl, checked = self._judge(m, res, pose, near, close, inl, c)
        if ok and MAX_AT_BOUND is not None and len(_at_bound(m, res.params)) > MAX_AT_BOUND:
            ok = False  # squeezed into the model: something else
        # the sensor's free-space evidence in the same units: the points the model's
        # visible surface should have shown where it saw through or nothing, each
        # costing what an explained point gains
        unexpl = min(max(1.0 - score, 0.0), 0.9)
        gain -= GAIN_CAP_LOG * len(inl) * unexpl / (1.0 - unexpl)
        return ok, score, inl, checked, gain

    def _judge(self, m: _Model, res: FitResult, pose: Pose, near: np.ndarray,
               close: np.ndarray, inl: np.ndarray, c: np.ndarray
               ) -> tuple[bool, float, np.ndarray, FitResult]:
        """The tests of :meth:`_verify` on the free points ``near`` the placed model
        (``close``: within three noise levels of its surface; ``inl``: those off the
        support; ``c``: its centre ``(3,)``)."""
        if len(inl) < self.mp:
            return False, 0.0, inl, res
        # of the free points inside the fitted model's box (a neighbour's points outside
        # it are not the model's business), enough must lie on its surface
        # (its box from its surface samples at the fitted parameters: cheaper than the
        # field's bounds, which are computed anew for every parameter vector)
        surf, _ = self._surface_at(m, res.params)
        b = np.array([surf.min(axis=0), surf.max(axis=0)])
        q = (self.P[near] - pose.translation) @ pose.rotation
        pad = 3.0 * self.sigma + 0.02 * m.radius
        boxed = np.all((q >= b[0] - pad) & (q <= b[1] + pad), axis=1) & ~self.support[near]
        if close[boxed].sum() < MIN_INLIER_FRACTION * boxed.sum():
            return False, 0.0, inl, res
        if self.vp is None:
            frac = len(inl) / max(len(near[~self.support[near]]), 1)
            return frac >= 0.5, float(frac), inl, res
        dist = float(np.linalg.norm(c - self.vp))
        if dist <= m.radius:
            return True, 1.0, inl, res
        ang = math.asin(min(1.0, (1.2 * m.radius) / dist))
        axis = (c - self.vp) / dist
        view = np.flatnonzero(self.dirs @ axis >= math.cos(ang))
        checked = check_fit(m.shape, self.P[view], res, viewpoint=self.vp,
                            f_scale=max(self.sigma, 1e-9), backend=m.backend)
        q = checked.quality
        if not q.get("visible_checked"):
            return True, float(len(inl) / max(len(near), 1)), inl, checked
        unexpl = float(q["visible_unexplained"])
        ok = q["visible_see_through"] <= MAX_SEE_THROUGH and unexpl <= MAX_UNEXPLAINED
        return bool(ok), 1.0 - unexpl, inl, checked

    def _front_fraction(self, m: _Model, res: FitResult, inl: np.ndarray,
                        surf: np.ndarray) -> float:
        """The fraction of the rays on the fit ``res``'s visible surface that show a
        point of its own clusters floating in front of it (the first figure of
        :meth:`_ray_evidence`, which see)."""
        return self._ray_evidence(m, res, inl, surf)[0]

    def _ray_evidence(self, m: _Model, res: FitResult, inl: np.ndarray,
                      surf: np.ndarray) -> tuple[float, float]:
        """``(front, confirmed)``: what the sensor's rays through the fit ``res``'s
        bounding sphere show of it. Of the scan points whose rays pass within the fitted
        model's bounding sphere and hit the model:

        * ``front``: those whose measured range is over three noise levels short of the
          model's first hit, are off the support, unclaimed and in one of the clusters
          holding at least a tenth of the fit's inliers ``inl`` ``(K,)``, over those
          plus the rays whose range lies within three noise levels of the hit (the
          surface the scan confirms). A point in front of a model is an occluder when
          it belongs to another object; one of the object's own cluster there is
          structure the model lacks: a lamp laid over a sphere, whose side bulges out
          between the lamp's shade and base (right fits have 0-6 % there on the
          benchmark's seeds 0-29, noise tails). 0 when the fit has no own clusters.
        * ``confirmed``: the rays whose range lies within three noise levels of the
          hit, over all the rays that hit the model (confirmed, seen through, or
          hidden behind a nearer point, whoever's): how much of the model's silhouette
          the scan shows where the model says. A model whose silhouette is nearly all
          hidden rests on the few points it explains (a bookshelf fitted over a table
          behind another bookshelf: 6 %; right detections on seeds 0-39: 36 % or more).

        At most ``FRONT_RAYS`` rays are cast (an even stride over them: no random draw).
        ``surf``: the model's surface samples at ``res.params`` ``(K, 3)``, model frame
        (:meth:`_surface_at`). ``(0, 1)`` when the viewpoint is inside the model's
        bounding sphere or no ray hits."""
        lo, hi = surf.min(axis=0), surf.max(axis=0)
        mid = 0.5 * (lo + hi)
        cw = res.pose.apply(mid[None])[0]
        rad = float(np.linalg.norm(surf - mid, axis=1).max()) + 3.0 * self.sigma
        v = cw - self.vp
        dist = float(np.linalg.norm(v))
        if dist <= rad:
            return 0.0, 1.0
        rays = np.flatnonzero(self.dirs @ (v / dist) >= math.cos(math.asin(rad / dist)))
        if len(rays) > FRONT_RAYS:
            rays = rays[np.linspace(0, len(rays) - 1, FRONT_RAYS).astype(int)]
        tm = self._first_hits(m, res, rays, surf)
        _, rng_scan = self._ray_index()
        r = rng_scan[rays]
        hit = np.isfinite(tm)
        tol = 3.0 * self.sigma
        conf = int(np.count_nonzero(hit & (np.abs(r - np.where(hit, tm, 0.0)) <= tol)))
        n_hit = int(np.count_nonzero(hit))
        confirmed = conf / n_hit if n_hit else 1.0
        own = self._own_clusters(inl)
        if len(own) == 0:
            return 0.0, confirmed
        mine = np.isin(self.label[rays], own) & ~self.support[rays] & ~self.claimed[rays]
        if self.foreign is not None:
            mine &= ~self.foreign[rays]
        front = int(np.count_nonzero(hit & (r < np.where(hit, tm, 0.0) - tol) & mine))
        return (front / (conf + front) if conf + front else 0.0), confirmed

    def _tracer(self, m: _Model, params: dict, surf: np.ndarray | None = None) -> Any:
        """``m`` at ``params`` ready to sphere-trace (:func:`csdf.render.trace.trace_field`)
        in the box of its surface samples ``surf`` (model frame; :meth:`_surface_at` when
        None) padded by a twentieth of its diagonal and three noise levels."""
        from ..render.trace import trace_field

        if surf is None:
            surf, _ = self._surface_at(m, params)
        lo, hi = surf.min(axis=0), surf.max(axis=0)
        pad = 0.05 * float(np.linalg.norm(hi - lo)) + 3.0 * self.sigma
        return trace_field(m.shape, dict(params), m.backend, np.array([lo - pad, hi + pad]),
                           what="detect", check_ranges=False)

    def _first_hits(self, m: _Model, res: FitResult, rays: np.ndarray,
                    surf: np.ndarray | None = None) -> np.ndarray:
        """``(K,)`` the range from the viewpoint to the first hit of the fit ``res`` of
        ``m`` along the rays of the scan points ``rays`` ``(K,)`` (inf: no hit), traced
        as :meth:`_tracer` (``surf`` its surface samples, or None)."""
        from ..render.trace import sphere_trace

        fld = self._tracer(m, res.params, surf)
        R, t = np.asarray(res.rotation, dtype=float), np.asarray(res.translation, dtype=float)
        return sphere_trace(fld, (self.vp - t) @ R, self.dirs[rays] @ R).t

    def _intruders(self, m: _Model, res: FitResult, b: np.ndarray) -> float:
        """The fraction of the scan points off the support (and, standing on a surface
        above it, off that surface) inside the fit ``res``'s box
        (``b`` ``(2, 3)``, model frame, padded by three noise levels) that lie in the
        model's free space in front of it: the model ray-cast along each point's ray
        hits nothing, or hits more than three noise levels beyond the point. A model
        stretched over something else (a squat lamp over a cylinder, whose side the
        sensor saw where the lamp has only its stem; a stool over a piece of a table)
        has points floating inside it; a right fit has only its noise's tails and
        outliers there (0-17 % on the benchmark's 30 scenes, against 20-58 % for the
        false positives it rejects). 0 without points in the box."""
        from ..render.trace import sphere_trace, trace_field

        pad = 3.0 * self.sigma
        q = (self.P - res.translation) @ res.rotation
        keep = np.all((q >= b[0] - pad) & (q <= b[1] + pad), axis=1) & ~self.support
        if self.lift > 0.0:  # nor the surface it stands on (:meth:`best_lifted`)
            keep &= q[:, 2] > b[0, 2] + pad
        inb = np.flatnonzero(keep)
        if len(inb) == 0:
            return 0.0
        fld = trace_field(m.shape, dict(res.params), m.backend,
                          np.array([b[0] - 2 * pad, b[1] + 2 * pad]), what="detect",
                          check_ranges=False)
        _, rng_scan = self._ray_index()
        tm = sphere_trace(fld, (self.vp - res.translation) @ res.rotation,
                          self.dirs[inb] @ res.rotation).t
        free = np.where(np.isfinite(tm), rng_scan[inb] < tm - pad, True)
        return float(free.mean())

    def best_for(self, idx: np.ndarray) -> Detection | None:
        """Steps 4-7 for the points ``idx``: the best verified detection, or None."""
        self.band_rejected = False
        self.unfit = False
        span = _span(self.P[idx])
        fits = [m for m in self.models if span <= 2.0 * m.radius * SIZE_SLACK + 6 * self.sigma]
        self.too_wide = not fits
        if not fits:
            return None
        sub = self._subsample(idx, SCREEN_POINTS)
        S = self.P[sub]
        if self.plane is not None and self.upright:
            placed = [(*self._placed(m, idx, S), i) for i, m in enumerate(fits)]
            ranked = sorted(placed, key=lambda x: (x[0], x[2]))[:MODELS_REFINED]
            # a model whose best hypothesis costs over SCREEN_RATIO times the best
            # model's is not fitted (on seeds 0-29 the winner's cost was at most 1.33
            # times the best's; 80-85 % of the second and third were over 2)
            tries = [(fits[i], init) for c, init, i in ranked
                     if c <= SCREEN_RATIO * ranked[0][0]]
        else:
            tries = [(m, None) for m in fits]
        done = []  # per model tried: (model, init, base result or None, verified fits)
        own = []  # (verified fits, the fits on its own clusters alone) to add after the turns
        for m, init in tries:
            found = []
            joined = len(self.joined)
            res = self._candidate(m, idx, init, stand=STAND_FIRST and init is not None)
            if res is not None:
                ok, score, inl, checked, gain = self._verify(m, res)
                if ok:
                    found.append((gain, score, res, inl, checked))
                elif init is not None and self._explains_most(inl, idx):
                    # explained most of the points but failed: other parameter starts
                    self._other_params(m, idx, res, init, found)
                    if not found:
                        self._shrunk(m, idx, res, found)
                    if not found and OWN_REFIT and len(self.joined) > joined:
                        # it took another cluster as a piece of its object: without it,
                        # competing after the turns (a failed placement's turns are
                        # searched as before). (Only a cluster that no model tried
                        # before it in this search took counts: a second model's fit
                        # that takes the same one is not refitted. Refitting those too,
                        # by a record of each model's own takings, ran 80 refits instead
                        # of 60 over the benchmark's 300 seeds and changed no output.)
                        mine: list = []
                        self._add_verified(m, idx, init, mine, stand=STAND_FIRST,
                                           pieces=False)
                        own.append((found, mine))
            done.append((m, init, res, found))
        if self.plane is not None and self.upright:
            # the winner's best other yaws, and those of the placements of models the
            # screen ranked higher but whose fits failed (at most TURN_MODELS)
            win = [d for d in done if d[3]]
            turn = []
            if win:
                w = max(win, key=lambda d: max(f[0] for f in d[3]))
                turn = [w]
                ranked_above = done[:next(i for i, d in enumerate(done) if d is w)]
            else:
                ranked_above = done
            turn += [d for d in ranked_above if d[1] is not None and not d[3]][:TURN_MODELS]
            for m, init, _res, found in turn:
                base = max(found, key=lambda f: f[0])[2] if found else init
                self._turns(m, idx, base, found,
                            YAW_REFITS if found else YAW_REFITS_FAILED)
        for found, mine in own:
            found += mine
        best = None
        for m, init, _, found in done:
            if not found:
                continue
            top = max(found, key=lambda f: f[0])
            if best is None or top[0] > best[1][0]:
                best = (m, top, init)
        if best is None:
            self.unfit = bool(tries)
            return None
        m, top, init = best
        upright = self.plane is not None and self.upright and self.vp is not None
        if upright and 1.0 - top[1] > REFIT_UNEXPLAINED and init is not None:
            refits = self._refit_unexplained(m, idx, top, init)
            done.append((m, init, None, refits))
            top = max(refits, key=lambda f: f[0])
        if upright and TRIM_OVERHANG and init is not None:
            # a refit cut back to the points' footprint replaces the winner when it
            # explains TRIM_GAIN more (not a tie for the rays to break: a bookshelf
            # seen from the back fits as well a quarter turned, its panel as a side)
            cut = max(self._trimmed(m, idx, top), key=lambda f: f[0], default=None)
            if cut is not None and cut[0] > (1.0 + TRIM_GAIN) * top[0]:
                top = cut
                done.append((m, init, None, [top]))
            if TRIM_RIVALS is not None:
                m, top, init = self._trim_rivals(idx, done, (m, top, init))
        if self.vp is not None and RAY_TIE > 0.0:
            m, top, init = self._ray_tie(done, (m, top, init))
        if upright and HALF_TURN_MARGIN is not None:
            top = self._half_turn(m, top)
        if upright:
            top = self._resolve_yaw(m, idx, top)
        if upright and COMPLETE_LOSS is not None:
            top = self._completed(m, top)
        _, score, res, inl, checked = top
        if CANONICAL_SWAP:
            res, checked = _canonical(m, res), _canonical(m, checked)
        if not self._seen_right(m, res, inl):
            return None
        inl = self._own_inliers(inl, idx)
        return Detection(model=m.name, pose=Pose(res.rotation, res.translation),
                         params=dict(res.params), score=score, inliers=inl, shape=m.shape,
                         source=m.source, fit=checked)

    def _trim_rivals(self, idx: np.ndarray, done: list, best: tuple) -> tuple:
        """``best`` ``(model, item, init)``, the winner of the points ``idx`` after its
        own cut-back, or a rival cut back that beats it: each verified fit of ``done``
        (:meth:`best_for`'s) whose explained mass lies within ``TRIM_RIVALS`` of the
        winner's and whose pose differs from it (:meth:`_rivals`) is cut back to the
        points' footprint (:meth:`_trimmed`) and held back from the ends of its
        ranges (:meth:`_shrunk`); the best of those of each rival, when it explains
        more than the rival, joins ``done`` (where the ray tie may choose it) and
        replaces the winner when it explains ``TRIM_GAIN`` more. A bookshelf seen from
        its side, fitted the right way round with its depth pushed to its bound, lost
        to its half turn by 2 %; held back, it won."""
        if self._doubt(best[0])[2]:
            return best  # its turns are :meth:`_resolve_yaw`'s
        win = best
        for m, init, f in self._rivals(done, best, TRIM_RIVALS):
            cuts = self._trimmed(m, idx, f)
            self._shrunk(m, idx, f[2], cuts)
            cut = max(cuts, key=lambda c: c[0], default=None)
            if cut is None or cut[0] <= f[0]:
                continue
            done.append((m, init, None, [cut]))
            if cut[0] > (1.0 + TRIM_GAIN) * win[1][0]:
                win = (m, cut, init)
        return win

    def _rivals(self, done: list, best: tuple, within: float) -> list:
        """The verified fits ``(model, init, item)`` of ``done`` (:meth:`best_for`'s)
        whose explained mass lies within the fraction ``within`` of that of ``best``
        ``(model, item, init)`` and whose pose differs from its (by a noise level or
        ``YAW_SAME`` degrees)."""
        m0, top, _ = best
        floor = top[0] - within * abs(top[0])
        R0 = np.asarray(top[2].rotation, dtype=float)
        t0 = np.asarray(top[2].translation, dtype=float)
        out = []
        for m, init, _res, found in done:
            for f in found:
                if f is top or f[0] < floor:
                    continue
                turn = math.degrees(rotation_angle(R0, np.asarray(f[2].rotation, float)))
                if m is m0 and turn < YAW_SAME and np.linalg.norm(
                        np.asarray(f[2].translation, dtype=float) - t0) < self.sigma:
                    continue
                out.append((m, init, f))
        return out

    def _ray_tie(self, done: list, best: tuple) -> tuple:
        """``best`` ``(model, item, init)`` (an item of ``found``, as :meth:`_turns`'),
        the verified fit of the cluster with the most explained mass, or another of
        the fits ``done`` (:meth:`best_for`'s) whose explained mass lies within
        ``RAY_TIE`` of its and whose pose differs from it (by a noise level or
        ``YAW_SAME`` degrees): then each is ray-cast (:meth:`_ray_scores`, on the
        rays of :meth:`_ray_set` about the best, its own clusters counting in front)
        and the one that scores most wins, when it leads the best by ``RAY_MARGIN``
        explained points (they differ in their parameters too)."""
        m0, top, _ = best
        if self.plane is not None and self.upright and self._doubt(m0)[2]:
            return best  # its turns are :meth:`_resolve_yaw`'s, with finer rays
        rivals = [(m, f, init) for m, init, f in self._rivals(done, best, RAY_TIE)]
        if not rivals:
            return best
        rays = self._ray_set(m0, top[2])
        if len(rays) == 0:
            return best
        own = self._own_clusters(top[3])

        def score(m: _Model, f: tuple) -> float:
            R, t = np.asarray(f[2].rotation, float), np.asarray(f[2].translation, float)
            return float(self._ray_scores(m, dict(f[2].params), [(R, t)], rays, own)[0])

        ref = score(m0, top)
        win, lead = best, ref + RAY_MARGIN * GAIN_CAP_LOG
        for m, f, init in rivals:
            s = score(m, f)
            if s > lead:
                win, lead = (m, f, init), s
        return win

    def _half_turn(self, m: _Model, top: tuple) -> tuple:
        """The winner ``top`` (an item of ``found``, as :meth:`_turns`') of model ``m``,
        or the same fit turned half round about the support's normal through the
        centre of its bounds, at the same sizes, when the sensor's rays score that
        turn (:meth:`_ray_scores` on :meth:`_ray_set`'s rays, its own clusters
        counting in front) over ``HALF_TURN_MARGIN`` explained rays more and it passes
        verification. Not for a model whose half turn is a symmetry (a table's) or
        whose turn is in doubt (:meth:`_doubt`: a lamp's turns are
        :meth:`_resolve_yaw`'s). A bookshelf's back panel and its open front fit the
        same points when it is seen from the side, and the search's refits of the
        half turn move their sizes; turned at the winner's own sizes, the right
        turn scored 194 and 261 rays more than the winner on two of the
        benchmark's scans (scenes 13 and 41), and no right detection of the 300
        scans had a half turn that scored over three rays more. On fresh seeds the
        right half turns led by 29.5-248 and wrong ones by 12.2, 23.7 and 158.8: a
        lead of a few dozen rays is a close call on a bookshelf seen near side-on."""
        full, sym, doubt = self._doubt(m)
        if doubt or sym[int(np.argmin(np.abs(full - math.pi)))]:
            return top
        res = top[2]
        rays = self._ray_set(m, res)
        if len(rays) == 0:
            return top
        surf, _ = self._surface_at(m, res.params)
        R, t = np.asarray(res.rotation, dtype=float), np.asarray(res.translation, dtype=float)
        c = R @ (0.5 * (surf.min(axis=0) + surf.max(axis=0))) + t
        half = _yaw_matrix(self.plane[0], math.pi)
        R2, t2 = half @ R, half @ (t - c) + c
        s = self._ray_scores(m, dict(res.params), [(R, t), (R2, t2)], rays,
                             self._own_clusters(top[3]))
        if s[1] <= s[0] + HALF_TURN_MARGIN * GAIN_CAP_LOG:
            return top
        turned = dataclasses.replace(res, rotation=R2, translation=t2)
        ok, score, inl, checked, gain = self._verify(m, turned)
        return (gain, score, turned, inl, checked) if ok else top

    def _refit_unexplained(self, m: _Model, idx: np.ndarray, top: tuple,
                           init: FitResult | dict) -> list:
        """The winner ``top`` (an item of ``found``, as :meth:`_turns`') of model ``m``
        on the points ``idx``, fitted from the screen's start ``init``, leaves over
        ``REFIT_UNEXPLAINED`` of its visible surface unexplained (the sensor saw
        through it or nothing there): its parameters may have grown where nothing holds
        them (a bookshelf's depth at its bound). Fits from other parameter starts
        (:meth:`_other_params`) and, with ``SHRINK_PASSED``, fits held back from the
        ends of the ranges (:meth:`_shrunk`: a bookshelf grown 0.27 m wider and to its
        full depth over a chair beside it passed with 12 % unexplained) compete with it
        by explained mass, which counts that, and so do the ``NARROW_FITS`` best of
        these cut back to narrower widths and depths (:meth:`_narrowed`); returns them
        all, ``top`` first."""
        found = [top]
        self._other_params(m, idx, top[2], init, found)
        if SHRINK_PASSED:
            self._shrunk(m, idx, top[2], found)
        if NARROW_STEPS:
            for f in sorted(found, key=lambda f: -f[0])[:NARROW_FITS]:
                found += self._narrowed(m, idx, f[2])
        return found

    def _narrowed(self, m: _Model, idx: np.ndarray, res: FitResult) -> list:
        """Fits of ``m`` to the points ``idx`` with the width or the depth of the fit
        ``res`` (:func:`_extents`) cut back to each of ``NARROW_STEPS`` of it and held
        there, the model shifted to keep one side where it was (each side of each
        axis, the pose and the other parameters free); returns those that pass
        verification with their width and depth inside their ranges (items as
        :meth:`_turns`'; ``[]`` for a model without a width and a depth).

        The fit has no term for the space the sensor saw empty: a size that no point
        holds grows wherever a few points of a neighbour pull it, and a free refit
        from a narrower start grows back. A bookshelf seen from behind with a stool
        against its side (one cluster) was fitted 0.35 m wider over the stool, its
        far panel unseen and 8 % of its back seen through, from every start; held at
        0.62 m (it is 0.64 m wide), it explains as much with nothing seen through, and
        wins by explained mass."""
        ext = _extents(m)
        if ext is None:
            return []
        px, py, sx, sy = ext
        R = np.asarray(res.rotation, dtype=float)
        t = np.asarray(res.translation, dtype=float)
        surf, _ = self._surface_at(m, res.params)
        size = surf.max(axis=0) - surf.min(axis=0)
        rng = _ranges(m)
        out: list = []
        for a, (name, slope) in enumerate(((px, sx), (py, sy))):
            for frac in NARROW_STEPS or ():
                pv = dict(res.params)
                _resize(pv, name, -(1.0 - frac) * size[a], slope, rng)
                cut = (float(res.params[name]) - pv[name]) * slope  # after the range's clip
                if cut < TRIM_OVERHANG * self.sigma:
                    continue
                for side in (-1.0, 1.0):  # keep the high side, then the low side
                    shift = np.zeros(3)
                    shift[a] = -0.5 * side * cut
                    start = {"rotation": R, "translation": t + R @ shift, "params": pv}
                    found: list = []
                    self._add_verified(m, idx, start, found, held=(name,))
                    out += _sizes_inside(m, found, (px, py))
        return out

    def _trimmed(self, m: _Model, idx: np.ndarray, top: tuple) -> list:
        """Refits of the winner ``top`` (an item of ``found``, as :meth:`_turns`') of
        model ``m`` on the points ``idx`` cut back to the points' footprint: where the
        model reaches past the cluster's points along its width or depth
        (:func:`_extents`) by over ``TRIM_OVERHANG`` noise levels and
        ``TRIM_FRACTION`` of that extent, a start with those extents set to the
        points' and the model shifted with them; returns the refits that pass
        verification with their width and depth inside their ranges (items as
        :meth:`_turns`'; ``[]`` when nothing overhangs). A table seen end-on at the top
        of the image grew 0.4 m past its far legs into space the sensor never looked
        at, leaving those legs' points unexplained."""
        res = top[2]
        R = np.asarray(res.rotation, dtype=float)
        t = np.asarray(res.translation, dtype=float)
        surf, _ = self._surface_at(m, res.params)
        lo, hi = surf.min(axis=0), surf.max(axis=0)
        Q = (self.P[idx] - t) @ R
        Q = Q[(Q[:, 2] >= lo[2] - 3.0 * self.sigma) & (Q[:, 2] <= hi[2] + 3.0 * self.sigma)]
        if len(Q) < self.mp:
            return []
        qlo = np.percentile(Q[:, :2], 0.5, axis=0)
        qhi = np.percentile(Q[:, :2], 99.5, axis=0)
        over_lo, over_hi = qlo - lo[:2], hi[:2] - qhi
        need = np.maximum(TRIM_OVERHANG * self.sigma, TRIM_FRACTION * (hi[:2] - lo[:2]))
        over = np.maximum(over_lo, over_hi) > need
        # (the sizes' parameters are looked up only now: each costs a bounds search
        # the first time)
        ext = _extents(m) if over.any() else None
        if ext is None:
            return []
        px, py, sx, sy = ext
        rng = _ranges(m)
        pv = dict(res.params)
        shift = np.zeros(3)
        for a, (name, slope) in enumerate(((px, sx), (py, sy))):
            if not over[a]:
                continue
            new_lo, new_hi = lo[a] + max(over_lo[a], 0.0), hi[a] - max(over_hi[a], 0.0)
            _resize(pv, name, (new_hi - new_lo) - (hi[a] - lo[a]), slope, rng)
            shift[a] = 0.5 * (new_lo + new_hi) - 0.5 * (lo[a] + hi[a])
        start = {"rotation": R, "translation": t + R @ shift, "params": pv}
        found: list = []
        self._add_verified(m, idx, start, found, stand=True)
        # a refit that pushes the width or the depth to an end of its range holds a size
        # that no point holds either (a bookshelf's back panel fitted as its side, 0.45
        # m deep, explained 8 % more points than a wider fit)
        return _sizes_inside(m, found, (px, py))

    def _seen_right(self, m: _Model, res: FitResult, inl: np.ndarray) -> bool:
        """The last tests of a winner ``res`` of ``m`` with inliers ``inl`` (with a
        viewpoint; True without one): at most ``MAX_INTRUDERS`` of other points inside
        it (:meth:`_intruders`), at most ``MAX_FRONT`` of its rays seen in front of it
        and at least ``MIN_CONFIRMED`` confirmed (:meth:`_ray_evidence`)."""
        if self.vp is None:
            return True
        surf, _ = self._surface_at(m, res.params)
        box = np.array([surf.min(axis=0), surf.max(axis=0)])
        if self._intruders(m, res, box) > MAX_INTRUDERS:
            return False
        front, confirmed = self._ray_evidence(m, res, inl, surf)
        return front <= MAX_FRONT and confirmed >= MIN_CONFIRMED

    def _completed(self, m: _Model, top: tuple) -> tuple:
        """The winner ``top`` (an item of ``found``, as :meth:`_turns`') of ``m``, or
        the same fit grown to its default width or depth (:func:`_extents`) where it
        is narrower, towards the side the sensor did not see. Where the rest of an
        object is hidden its points bound its size only from below, and the fit
        shrinks to them: a table whose far half an occluder hid was fitted as its near
        half, 0.7 m short. Each size below its default is grown, not refitted, away
        from one end, from the other, and (when both pass) from both; a grown fit
        passes when it passes verification and the last tests (:meth:`_seen_right`)
        and explains at most ``COMPLETE_LOSS`` less than ``top`` (grown into space the
        sensor saw empty, it is seen through and fails). With ``COMPLETE_SWAPPED`` the
        form with exchanged parameters (:func:`_exchanged`) is grown too; the grown
        fit that explains most replaces ``top``."""
        ext = _extents(m)
        if ext is None:
            return top
        px, py, sx, sy = ext
        defaults = _defaults(m)
        forms = _traded_too(m, [top[2]]) if COMPLETE_SWAPPED else [top[2]]
        floor = (1.0 - COMPLETE_LOSS) * top[0]
        best = top
        for res in forms:
            cur = None  # this form grown so far
            for a, (name, slope) in enumerate(((px, sx), (py, sy))):
                base = res if cur is None else cur[2]
                if float(base.params[name]) >= defaults[name]:
                    continue
                grow = (defaults[name] - float(base.params[name])) * slope
                passed = []  # grown away from -x (-y), away from +x (+y), both ways
                for side in (-1.0, 1.0, 0.0):
                    if side == 0.0 and len(passed) < 2:
                        continue
                    shift = np.zeros(3)
                    shift[a] = 0.5 * side * grow
                    cand = dataclasses.replace(
                        base, translation=np.asarray(base.translation, dtype=float)
                        + np.asarray(base.rotation, dtype=float) @ shift,
                        params=dict(base.params, **{name: defaults[name]}))
                    ok, sc, il, ch, gain = self._verify(m, cand)
                    if (ok and gain >= floor and self._seen_right(m, cand, il)
                            and not self._seen_through_grown(m, base, cand)):
                        passed.append((gain, sc, cand, il, ch))
                if passed:  # both sides hidden: grown both ways, when that passes too
                    cur = passed[-1] if len(passed) == 3 else max(passed, key=lambda f: f[0])
            if cur is not None and (best is top or cur[0] > best[0]):
                best = cur
        return best

    def _seen_through_grown(self, m: _Model, res: FitResult, grown: FitResult) -> bool:
        """Whether the sensor saw through the part of the fit ``grown`` of ``m`` that
        ``res`` (the same fit before it was grown) lacks: of the rays that meet
        ``grown`` first where ``res`` has no surface as near (more than three noise
        levels farther, or none), more than ``COMPLETE_THROUGH`` and at least
        ``COMPLETE_THROUGH_RAYS`` measured a range over three noise levels beyond that
        hit (rays of :meth:`_ray_set` about ``grown``; False when
        ``COMPLETE_THROUGH`` is None). A right fit's grown part lies out of the
        sensor's view or behind nearer points, where its few seen-through rays graze
        thin parts (a table's legs) or edges; a bookshelf seen from behind in full,
        grown past its seen edge over a stool beside it, had 46 of its 47 such rays
        seen through."""
        if COMPLETE_THROUGH is None:
            return False
        rays = self._ray_set(m, grown)
        if len(rays) == 0:
            return False
        _, rng_scan = self._ray_index()
        before, after = (self._first_hits(m, r, rays) for r in (res, grown))
        tol = 3.0 * self.sigma
        new = np.isfinite(after) & ~(before <= after + tol)
        through = int(np.count_nonzero(rng_scan[rays][new] > after[new] + tol))
        return through >= COMPLETE_THROUGH_RAYS and through > COMPLETE_THROUGH * int(new.sum())

    def overlap(self, m: _Model, a: Detection, b: Detection) -> float:
        """How much the detections ``a`` and ``b`` of model ``m`` share space: the
        larger of the fractions of each's surface samples inside the other's box."""
        sa, sb = self._surface_at(m, a.params)[0], self._surface_at(m, b.params)[0]
        wa, wb = a.pose.apply(sa), b.pose.apply(sb)
        return max(float(np.mean(_in_box(wa, b.pose, sb.min(axis=0), sb.max(axis=0)))),
                   float(np.mean(_in_box(wb, a.pose, sa.min(axis=0), sa.max(axis=0)))))

    def spanning(self, m: _Model, a: Detection, b: Detection) -> list[FitResult]:
        """Starts for one fit of model ``m`` over the detections ``a`` and ``b`` that
        share no space: each one's fit (and each with its exchangeable sizes traded,
        :func:`_swaps`) grown along the model axis nearest the line between the two
        (its width or depth parameter, :func:`_extents`) to reach over both and moved
        to their middle; only those whose surface between the two (outside both
        detections' boxes) the sensor could not see for nearer points
        (``MERGE_HIDDEN`` of it, and at least ``MERGE_HIDDEN_SAMPLES`` surface samples
        there; with a viewpoint). Empty when there are none: two objects side by side
        with nothing in front of the space between them stay two."""
        ext = _extents(m)
        if ext is None or self.vp is None or a.fit is None or b.fit is None:
            return []
        names, slopes = (ext[0], ext[1]), (ext[2], ext[3])
        rng = _ranges(m)
        fs = self._fs_wide(m)
        surfs = [self._surface_at(m, d.params)[0] for d in (a, b)]
        boxes = [(d.pose, s.min(axis=0) - fs, s.max(axis=0) + fs) for d, s in zip((a, b), surfs)]
        world = [d.pose.apply(s) for d, s in zip((a, b), surfs)]
        ca, cb = (w.mean(axis=0) for w in world)
        out = []
        for f in _traded_too(m, [a.fit, b.fit]):
            R, t = np.asarray(f.rotation, float), np.asarray(f.translation, float)
            c = R @ m.centre + t
            u = (cb - ca) @ R  # the line between the two in this fit's model frame
            ax = 0 if abs(u[0]) >= abs(u[1]) else 1
            if abs(u[ax]) < 0.5 * float(np.linalg.norm(u)):
                continue  # the two lie along neither axis
            # the union's extent along that axis, and this fit's
            along = [(wc - c) @ R[:, ax] for wc in world]
            lo = min(float(v.min()) for v in along)
            hi = max(float(v.max()) for v in along)
            own = self._surface_at(m, f.params)[0][:, ax]
            grow = (hi - lo) - float(own.max() - own.min())
            name = names[ax]
            v = float(f.params[name]) + grow / slopes[ax]
            if grow <= 0.0 or not rng[name][0] <= v <= rng[name][1]:
                continue
            params = dict(f.params, **{name: v})
            surf = self._surface_at(m, params)[0]
            # moved so that its extent along the axis is the union's (about ``c``)
            mid = 0.5 * float(surf[:, ax].max() + surf[:, ax].min()) - float(m.centre[ax])
            start = dataclasses.replace(f, translation=t + (0.5 * (lo + hi) - mid) * R[:, ax],
                                        params=params)
            # its surface between the two: hidden from the sensor?
            S = surf @ R.T + start.translation
            X = S[~np.any([_in_box(S, *box) for box in boxes], axis=0)]
            if len(X) < MERGE_HIDDEN_SAMPLES or np.mean(self._occluded(X, fs)) < MERGE_HIDDEN:
                continue
            out.append(start)
        return out

    def merged(self, m: _Model, a: Detection, b: Detection,
               starts: list[FitResult] | None = None) -> Detection | None:
        """One detection of model ``m`` (that of ``a`` and ``b``) fitted to both's
        inliers from each's fit, and each's with its exchangeable sizes traded
        (:func:`_swaps`), or from ``starts`` when given (:meth:`spanning`), the best by
        explained mass; or None (and nothing changed) unless that one passes
        verification and the last tests (:meth:`_seen_right`), explains
        ``MERGE_COVER`` of those points, and more points than each alone."""
        idx = np.union1d(a.inliers, b.inliers)
        was = self.claimed[idx].copy()
        self.claimed[idx] = False
        if starts is None:
            # each also with its exchangeable sizes traded (the same surface turned a
            # quarter): the two halves of a table were each fitted a quarter turned,
            # their long side its width, whose range stopped the fit of both at 1.2 m
            starts = _traded_too(m, [d.fit for d in (a, b) if d.fit is not None])
        best = None
        for start in starts:
            res = self._candidate(m, idx, start, stand=True)
            if res is None:
                continue
            ok, score, inl, checked, gain = self._verify(m, res)
            if ok and (best is None or gain > best[0]):
                best = (gain, score, res, inl, checked)
        if best is not None:
            _, score, res, inl, checked = best
            if CANONICAL_SWAP:
                res, checked = _canonical(m, res), _canonical(m, checked)
            inl = self._own_inliers(inl, idx)
            if (np.isin(idx, inl).mean() >= MERGE_COVER
                    and len(inl) > max(len(a.inliers), len(b.inliers))
                    and self._seen_right(m, res, inl)):
                self.claimed[inl] = True
                return Detection(model=m.name, pose=Pose(res.rotation, res.translation),
                                 params=dict(res.params), score=score, inliers=inl,
                                 shape=m.shape, source=m.source, fit=checked)
        self.claimed[idx] = was
        return None

    def _own_inliers(self, inl: np.ndarray, idx: np.ndarray) -> np.ndarray:
        """The inliers ``inl`` ``(K,)`` (point indices) of a detection on the points
        ``idx`` that it claims: those of the clusters of ``idx``, of clusters at least
        ``PIECE_INSIDE`` of whose free points it explains (a piece of the object cut
        off by an occluder) and of no cluster (outliers near its surface); not a
        neighbour's points that happen to lie within three noise levels of its surface
        (a bookshelf explained 86 points of a lamp standing beside it at 2.2 cm noise,
        and the lamp, left with 225 of its 311 points, was fitted turned wrong)."""
        lab = self.label[inl]
        if not (lab >= 0).any():
            return inl
        free = np.bincount(self.label[(self.label >= 0) & ~self.claimed],
                           minlength=len(self.sizes))
        keep = _joined(self.label, lab, idx, np.maximum(free, 1))
        return inl[(lab < 0) | np.isin(lab, keep)]

    def _upright_shape(self, m: _Model) -> Any:
        """``m``'s shape turned about its z axis and shifted along its x and y axes by
        three added parameters (:data:`UPRIGHT_PARAMS`), so that a fit of the
        parameters alone moves the model only in the ways an object standing on the
        support can move; None when the model is not a 3D :class:`csdf.Shape` (built
        once per model)."""
        if m.upright_shape is None:
            from ..expr import param
            from ..shapes import Shape

            aug: Any = False
            if isinstance(m.shape, Shape) and m.shape.dim == 3:
                yaw, dx, dy = UPRIGHT_PARAMS
                r = 2.0 * m.radius
                try:
                    aug = m.shape.rotate(param(yaw, 0.0, -2 * math.pi, 2 * math.pi), "z") \
                        .translate((param(dx, 0.0, -r, r), param(dy, 0.0, -r, r), 0.0))
                except CsdfError:
                    aug = False
            m.upright_shape = aug
        return m.upright_shape or None

    def _polish(self, m: _Model, idx: np.ndarray, res: FitResult) -> FitResult | None:
        """``res`` (an upright fit of ``m`` to the points ``idx``) fitted again with the
        model held upright on the support: its parameters, its turn about the support's
        normal and its shift along the support, at once (:meth:`_upright_shape`), on the
        free points off the support within ``POLISH_BAND`` noise levels of its surface.
        The free fit that :meth:`_upright_fit` stands upright tilts, shifts and turns a
        tall thin-walled model to fit its noisy points, and the parameters then fitted
        with the snapped pose held make up for it: a lamp's shade came out 4 cm short,
        its stem too long, and with them its spokes, the only mark of its turn, in the
        wrong place. The band is gathered again about each round's surface for up to
        ``POLISH_ROUNDS`` rounds, while it grows by more than ``POLISH_GROWN``: points
        the first band left out (a shade's upper rim, when the winner's shade was
        short) then join the fit. None when it cannot be done."""
        aug = self._upright_shape(m)
        if aug is None:
            return None
        c = res.pose.apply(m.centre[None])[0]
        pts = np.flatnonzero(~self.claimed & ~self.support & (
            np.linalg.norm(self.P - c, axis=1) <= 1.2 * m.radius + 3 * self.sigma))
        out, last = None, np.zeros(0, dtype=np.intp)
        for _ in range(POLISH_ROUNDS):
            fld = as_field(m.shape, res.params, pose=res.pose, backend=m.backend,
                           what="detect", check_ranges=False)
            d = np.abs(np.asarray(fld.value(self.P[pts]), dtype=float))
            band = pts[d <= POLISH_BAND * self.sigma]
            if len(band) < self.mp:
                return out
            if out is not None and len(np.setdiff1d(band, last, assume_unique=True)) <= \
                    POLISH_GROWN * len(last):
                return out
            r = self._polish_round(m, aug, res, band)
            if r is None:
                return out
            out = res = r
            last = band
        return out

    def _polish_round(self, m: _Model, aug: Any, res: FitResult, band: np.ndarray
                      ) -> FitResult | None:
        """One round of :meth:`_polish`: ``res`` refitted with ``m``'s upright shape
        ``aug`` (its parameters, turn and shift) to the points ``band`` ``(K,)``
        (indices; at most ``POLISH_POINTS`` of them, a seeded subsample); None when the
        fit fails."""
        F = self._subsample(band, POLISH_POINTS)
        pv = {**dict(res.params), **dict.fromkeys(UPRIGHT_PARAMS, 0.0)}
        try:
            r = fit(aug, self.P[F], init={"rotation": res.rotation,
                                          "translation": res.translation, "params": pv},
                    estimate=("params",), loss="cauchy",
                    f_scale=self._fs_fit(m), viewpoint=self.vp,
                    max_iter=POLISH_ITER, escape=False, debias=False, backend=m.backend,
                    check_ranges=False, check_visible=False)
        except CsdfError:
            return None
        yaw, dx, dy = (float(r.params[k]) for k in UPRIGHT_PARAMS)
        R = np.asarray(res.rotation, dtype=float)
        rot = R @ _rz(yaw)
        shift = np.asarray(res.translation, dtype=float) + R @ np.array([dx, dy, 0.0])
        params = {k: v for k, v in r.params.items() if k not in UPRIGHT_PARAMS}
        return dataclasses.replace(r, rotation=rot, translation=shift, params=params)

    def _other_params(self, m: _Model, idx: np.ndarray, res: FitResult,
                      init: FitResult | dict, found: list) -> None:
        """A fit of ``m`` from the screen's start ``init`` explained most of the points
        ``idx`` but failed verification: the parameters often trade off along a valley
        (a lamp's shade grown down over its stem, seen through below). Fits again from
        ``res``'s pose with the next ``RETRY_STARTS`` parameter sets of the model's bank
        (those whose height is nearest the cluster's top, the defaults first, skipping
        ``init``'s) and appends those that pass verification to ``found`` (items as
        :meth:`_turns`')."""
        nrm, off = self._standing()
        top = float(np.percentile(self.P[idx] @ nrm - off, 99.0))
        order = 1 + np.argsort(np.abs(m.heights[1:] - top), kind="stable")
        used = dict(init.params if isinstance(init, FitResult) else init.get("params") or {})
        defaults = _defaults(m)
        tried = 0
        for k in [0, *order.tolist()]:
            if tried >= RETRY_STARTS:
                break
            pv = m.starts[k]
            full = {**defaults, **(pv or {})}
            if all(abs(float(full[n]) - float(used.get(n, defaults[n]))) <= 1e-12
                   for n in full):
                continue
            start = {"rotation": res.rotation, "translation": res.translation,
                     "params": dict(pv or {})}
            self._add_verified(m, idx, start, found)
            tried += 1

    def _shrunk(self, m: _Model, idx: np.ndarray, res: FitResult, found: list,
                steps: tuple[float, ...] | None = None) -> None:
        """A fit ``res`` of ``m`` to the points ``idx`` with parameters at an end of their
        ranges (within ``AT_BOUND`` of the span): a size no point holds (the side of a
        bookshelf the sensor does not see), which the fit pushes out until the model
        reaches into space the sensor saw empty (seen through: verification fails).
        Fits again from ``res``'s pose with those parameters set ``steps`` (default
        ``SHRINK_STEPS``) of the way back to their defaults and every parameter held
        (the pose alone refitted, then stood upright) and appends those that pass
        verification to ``found`` (items as :meth:`_turns`'), where explained mass,
        which counts the surface seen through, judges them against the rest. One pose
        fit a step, only for failed fits with a parameter at a bound."""
        at = _at_bound(m, res.params)
        if not at:
            return
        names = [n for n, _, _ in at]
        ends = [(e, d) for _, e, d in at]
        # every parameter held, not only those at a bound: the sizes a single view does
        # not hold trade against each other (a bookshelf seen side-on, its depth held at
        # the default, grew its width instead: 0.112 d, a false positive)
        held = tuple(p.name for p in m.fld.program.params)
        for frac in SHRINK_STEPS if steps is None else steps:
            pv = dict(res.params)
            pv.update({n: e + frac * (d - e) for n, (e, d) in zip(names, ends)})
            start = {"rotation": res.rotation, "translation": res.translation, "params": pv}
            self._add_verified(m, idx, start, found, held=held)

    def _ray_set(self, m: _Model, res: FitResult) -> np.ndarray:
        """Indices of the scan points whose rays score the turns of the fit ``res`` of
        ``m`` (:meth:`_ray_scores`): every point (claimed and support points included:
        they are free space too) whose ray passes within the fitted model's bounding
        sphere, widened by three noise levels, and that does not lie in front of it (an
        occluder is no evidence about the model): at most ``RAY_INSIDE`` of those
        within the sphere and ``RAY_BACKGROUND`` of those behind it (seeded
        subsamples)."""
        cw, rad = self._sphere(m, res)
        v = cw - self.vp
        dist = float(np.linalg.norm(v))
        if dist <= rad:
            cone = np.ones(len(self.P), dtype=bool)
        else:
            cone = self.dirs @ (v / dist) >= math.cos(math.asin(rad / dist))
        _, rng_scan = self._ray_index()
        rays = np.flatnonzero(cone & (rng_scan >= dist - rad))
        inside = np.linalg.norm(self.P[rays] - cw, axis=1) <= rad
        within, behind = rays[inside], rays[~inside]
        return np.sort(np.concatenate([self._subsample(within, RAY_INSIDE),
                                       self._subsample(behind, RAY_BACKGROUND)]))

    def _ray_scores(self, m: _Model, params: dict, poses: list, rays: np.ndarray,
                    own: np.ndarray | None = None, spread: float = 0.0) -> np.ndarray:
        """``(H,)`` how well each pose ``(R, t)`` of ``m`` at ``params`` predicts the
        ranges the sensor measured along the rays of the scan points ``rays`` ``(K,)``:
        the model is ray-cast along each, and a ray scores :func:`_gain` of its range
        residual where the model's first hit lies within three noise levels of the
        measured range, ``-GAIN_CAP_LOG`` where the sensor saw farther than it by more
        (through the model), and nothing where the model is hidden (the sensor saw
        nearer) or missed, unless the nearer point belongs to one of the clusters
        ``own`` (cluster labels ``(L,)``, the fit's own; unclaimed and off the
        support): a point of the object's own cluster in front of the model is
        structure the model lacks there, not an occluder, and costs ``GAIN_CAP_LOG``
        too. (A lamp turned wrong has its spokes where the sensor saw through, and the
        true spokes' points float in front of its shade: both count against it; only
        the first did before, and the right turn's lead on a lamp of 1,100 points was
        3.6, under the margin.) A range sensor's noise lies along its rays, so this
        sees thin parts (a lamp's spokes) that the points' distances to the surface,
        blurred by the noise in every direction, do not.

        ``spread`` (scene units, > 0): each ray is also cast as four parallel rays
        shifted across it by ``spread``, and the nearest hit of the five is the
        model's range on that ray: the model dilated by ``spread`` in the sensor's
        image. A thin part placed a few millimetres off by its parameters (a lamp's
        5 mm spokes, whose shade parameters a fit to points at 11-23 mm noise leaves
        3-7 mm off) then still meets the rays that saw it, and a wrong turn's spokes
        block more of the rays that saw the shade's inside. (The grown outline sees
        through too, alike at every turn of a model that is symmetric but for its
        thin parts.)"""
        from ..render.trace import sphere_trace

        fld = self._tracer(m, params)
        _, rng_scan = self._ray_index()
        D = self.dirs[rays]
        offsets = [np.zeros((len(rays), 3))]
        if spread > 0.0:
            # parallel rays shifted across the ray by ``spread`` (four ways): the
            # nearest hit of the five is the model's range there, as if the model
            # were dilated by ``spread`` in the sensor's image
            u, v = tangent_frames(D)
            offsets += [spread * u, -spread * u, spread * v, -spread * v]
        Dm = np.concatenate([D @ R for R, _ in poses])
        tm = np.full(len(Dm), np.inf)
        for off in offsets:
            O = np.concatenate([(self.vp + off - t) @ R for R, t in poses])
            tm = np.fmin(tm, sphere_trace(fld, O, Dm).t)
        tm = tm.reshape(len(poses), len(rays))
        r = rng_scan[rays][None, :] - tm
        hit = np.isfinite(tm)
        a = np.abs(np.where(hit, r, 0.0))
        g = np.where(hit & (a <= 3.0 * self.sigma), _gain(a, self.sigma), 0.0)
        g = np.where(hit & (r > 3.0 * self.sigma), -GAIN_CAP_LOG, g)
        if own is not None and len(own):
            mine = (np.isin(self.label[rays], own) & ~self.support[rays]
                    & ~self.claimed[rays])[None, :]
            g = np.where(hit & mine & (r < -3.0 * self.sigma), -GAIN_CAP_LOG, g)
        return g.sum(axis=1)

    def _yaw_scan_rays(self, m: _Model, res: FitResult, rays: np.ndarray,
                       angles: np.ndarray, own: np.ndarray | None = None,
                       spread: float = 0.0) -> tuple[np.ndarray, list]:
        """The fit ``res`` of ``m`` turned about the vertical through its own origin by
        each of ``angles`` ``(Y,)`` (radians): ``(ray-cast scores (Y,)
        (:meth:`_ray_scores` on the rays of ``rays``, ``own`` its own clusters),
        poses)``. (The model's origin is
        the axis its author built it about, a lamp's or a stool's; the centre of sampled
        surface points is off it by the samples' scatter, and a turn about that would
        move the whole model.)"""
        poses = self._turned_in_place(res, angles)
        return self._ray_scores(m, dict(res.params), poses, rays, own, spread), poses

    def _turned_in_place(self, res: FitResult, angles: np.ndarray) -> list:
        """The poses ``(R, t)`` of the fit ``res`` turned about the support's normal
        (without a support, or with upright search off, about the fit's own z axis)
        through its own origin by each of ``angles`` ``(Y,)`` (radians)."""
        t = np.asarray(res.translation, dtype=float)
        axis = (self.plane[0] if self.plane is not None and self.upright
                else np.asarray(res.rotation, dtype=float)[:, 2])
        return [(_yaw_matrix(axis, th) @ res.rotation, t) for th in angles]

    def _turned_by(self, res: FitResult, angle: float) -> FitResult:
        """The fit ``res`` turned about the support's normal through its own origin by
        ``angle`` (radians; :meth:`_turned_in_place`)."""
        return dataclasses.replace(
            res, rotation=self._turned_in_place(res, np.array([angle]))[0][0])

    def _turn_profile(self, m: _Model, angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """How turns ``angles`` ``(Y,)`` (radians) about the model's own z axis move its
        surface at its default parameters (whose surface samples lie exactly on it;
        samples moved onto other parameters can miss a thin part): ``(symmetric (Y,)
        bool, moved (Y,))``. A turn is a symmetry when the field at its turned surface
        samples stays within ``1e-3`` of the model's diameter of its value at the samples
        (as :func:`csdf.metrics.symmetries` tests): the same pose, not a competing one;
        ``moved`` is the fraction of the samples whose value it changes by more than
        three noise levels. The samples are the model's own from a mesh refined for
        thin parts (:attr:`_Model.fine`): at 48 voxels a bookshelf lost its 6 mm back
        panel, and its half turn moved none of them."""
        if m.fine is None:
            from ..metrics import model_points

            m.fine = model_points(m.fld, SURFACE_SAMPLES, resolution=None)
        q = np.concatenate([m.fine @ _rz(float(a)) for a in angles])  # R(a)^T x
        f = np.asarray(m.fld.value(q), dtype=float).reshape(len(angles), -1)
        # against the samples' own values (a mesh sample may lie a few millimetres off
        # the surface: a table's did by 2.7 mm, and its half turn was not a symmetry)
        d = np.abs(f - np.asarray(m.fld.value(m.fine), dtype=float)[None, :])
        return d.max(axis=1) <= 2e-3 * m.radius, (d > 3.0 * self.sigma).mean(axis=1)

    def _doubt(self, m: _Model) -> tuple[np.ndarray, np.ndarray, bool]:
        """``(turns (Y,) radians, RAY_STEP degrees apart over a full turn, symmetric
        (Y,) bool, in doubt)``: whether ``m`` has a turn about its own z axis, at least
        ``YAW_SAME`` degrees from every symmetry (a small turn moves little of any
        model), that moves less than ``YAW_DOUBT`` of its surface by more than three
        noise levels (:meth:`_turn_profile`); computed once a run and model."""
        key = id(m)
        if key not in self.doubts:
            full = np.radians(np.arange(0.0, 360.0, RAY_STEP))
            sym, moved = self._turn_profile(m, full)
            sym[0] = True
            gap = np.abs(full[:, None] - full[sym][None, :])
            far = np.min(np.minimum(gap, 2.0 * math.pi - gap), axis=1) >= math.radians(
                YAW_SAME)
            self.doubts[key] = (full, sym, bool(np.any(far & (moved < YAW_DOUBT))))
        return self.doubts[key]

    def _doubt_turns(self, m: _Model) -> tuple[np.ndarray, float] | None:
        """``(turns (Y,) radians, period)``: the turns ``RAY_STEP`` degrees apart over
        one period (radians) of ``m``'s symmetry about its own z axis, from 0, when its
        turn is in doubt (:meth:`_doubt`); None otherwise."""
        if not self._doubt(m)[2]:
            return None
        return self._period_turns(m)

    def _period_turns(self, m: _Model) -> tuple[np.ndarray, float]:
        """``(turns (Y,) radians, period)``: the turns ``RAY_STEP`` degrees apart over
        one period (radians) of ``m``'s symmetry about its own z axis (:meth:`_doubt`),
        from 0."""
        full, sym, _ = self._doubt(m)
        nz = np.flatnonzero(sym[1:])
        period = float(full[1 + nz[0]]) if len(nz) else 2.0 * math.pi
        return full[full < period - 1e-9], period

    def _resolve_yaw(self, m: _Model, idx: np.ndarray, top: tuple) -> tuple:
        """The winner ``top`` (an item of ``found``, as :meth:`_turns`') of model ``m``
        on the points ``idx``, or the same model better turned.

        Only when its turn is in doubt: the model has a turn about its own z axis, not
        a symmetry, that moves less than ``YAW_DOUBT`` of its surface by more than three
        noise levels (:meth:`_turn_profile`; a lamp, whose three 5 mm spokes under the
        shade are its only mark). Then the winner is refitted held upright
        (:meth:`_polish`: its parameters, which place the spokes, come out right) and
        ray-cast (:meth:`_ray_scores`, rays spread by ``RAY_SPREAD`` noise levels) at
        turns ``RAY_STEP`` degrees apart over one period of its symmetry about that
        axis; if another turn scores more than
        ``TURN_RAY_MARGIN`` explained points more at the refit's parameters, that turn
        is a candidate too (and, with ``TURN_REFITS``, the model refitted from it; none by
        default: the refit's free turn drifted back to a wrong one). The refit
        replaces the winner when its rays score more by the margin, and the turned
        candidate, if it passes verification, replaces that when it scores more than
        the refit's own turn by ``TURN_RAY_MARGIN`` and more than the choice. A winner
        that neither replaces is scanned the same way at its own parameters
        (``ORIG_TURNS``) and turned when a turn scores ``TURN_RAY_MARGIN`` more there
        and passes verification."""
        res = top[2]
        turns = self._doubt_turns(m)
        if turns is None:
            return top
        angles, _ = turns
        rays = self._ray_set(m, res)
        if len(rays) == 0:
            return top
        labs = self._own_clusters(top[3])
        spread = RAY_SPREAD * self.sigma
        score, _ = self._yaw_scan_rays(m, res, rays, angles[:1], labs, spread)
        margin = RAY_MARGIN * GAIN_CAP_LOG
        # one turn against another at the same parameters (TURN_REFITS = 0) needs no
        # margin for the parameters' differences
        turn_margin = (TURN_RAY_MARGIN if TURN_REFITS == 0 else RAY_MARGIN) * GAIN_CAP_LOG
        orig = (float(score[0]), top)
        own = None  # the winner refitted upright at its own turn
        cands = []  # the turned candidates
        start = res
        for k in range(1 + TURN_REFITS):
            r = self._polish(m, idx, start)
            if r is None:
                break
            ok, sc, il, ch, gain = self._verify(m, r)
            if not ok:
                break
            s2, poses = self._yaw_scan_rays(m, r, rays, angles, labs, spread)
            if k == 0:
                own = (float(s2[0]), (gain, sc, r, il, ch))
            else:
                cands.append((float(s2[0]), (gain, sc, r, il, ch)))
            i = int(np.argmax(s2))
            if i == 0 or s2[i] - s2[0] <= turn_margin:
                break
            start = dataclasses.replace(r, rotation=poses[i][0])
            ok, sc, il, ch, gain = self._verify(m, start)
            if ok:
                cands.append((float(s2[i]), (gain, sc, start, il, ch)))
        # the parameters: the upright refit replaces the winner's free fit when its
        # rays score more by the margin; the turn: a turned candidate replaces that when
        # it scores more than the winner's own turn refitted the same way (a turn is
        # not judged by the other parameters of a fit made another way) by the margin
        # and more than the choice so far
        best = orig
        if own is not None and own[0] - orig[0] > margin:
            best = own
        if cands:
            turned = max(cands, key=lambda c: c[0])  # the first of equals
            ref = own[0] if own is not None else orig[0]
            if turned[0] - ref > turn_margin and turned[0] > best[0]:
                best = turned
        if best is orig and ORIG_TURNS:
            # the winner stays as it was fitted: its own turn is judged at its own
            # parameters too (the refit's turns were compared with it across two sets
            # of parameters, which differ in the rays they explain by more than a turn
            # does: a lamp whose free fit's turn was 90 degrees off by its own rays, by
            # 35 explained points, stayed)
            s3, poses = self._yaw_scan_rays(m, res, rays, angles, labs, spread)
            i = int(np.argmax(s3))
            if i != 0 and s3[i] - s3[0] > turn_margin:
                start = dataclasses.replace(res, rotation=poses[i][0])
                ok, sc, il, ch, gain = self._verify(m, start)
                if ok:
                    return (gain, sc, start, il, ch)
        return best[1]

    def _settle_rays(self, det: Detection) -> tuple[_Model, np.ndarray, np.ndarray, float] | None:
        """``(model, rays (K,), own clusters (L,), period)`` that judge the turn of
        ``det`` (:meth:`_ray_set`, :meth:`_own_clusters`, the period of its model's
        symmetry about its axis, radians); None when its turn is not in doubt
        (:meth:`_doubt`: every turn, not a symmetry, moves ``YAW_DOUBT`` of its surface
        or more), or without a viewpoint, a support, upright search or rays."""
        if self.plane is None or self.vp is None or not self.upright or det.fit is None:
            return None
        m = next(mm for mm in self.models if mm.name == det.model)
        turns = self._doubt_turns(m)
        if turns is None:
            return None
        rays = self._ray_set(m, det.fit)
        if len(rays) == 0:
            return None
        return m, rays, self._own_clusters(det.inliers), turns[1]

    def _settle_scores(self, m: _Model, res: FitResult, rays: np.ndarray, own: np.ndarray,
                       period: float) -> tuple[np.ndarray, np.ndarray]:
        """``(turns (Y,) radians from the fit's own, scores (Y,))``: the turns of the fit
        ``res`` of ``m`` about the support's normal ``SETTLE_STEP`` degrees apart over
        one ``period``, from its own (0), scored at its own parameters by the rays
        ``rays`` cast without the spread (:meth:`_ray_scores`; ``own``, its own
        clusters)."""
        angles = np.radians(np.arange(0.0, math.degrees(period) - 1e-9, SETTLE_STEP))
        s = self._ray_scores(m, dict(res.params), self._turned_in_place(res, angles),
                             rays, own)
        return angles, s

    def _ray_refit(self, m: _Model, res: FitResult, rays: np.ndarray, own: np.ndarray
                   ) -> FitResult:
        """The fit ``res`` of ``m`` with its parameters refitted to the rays ``rays``
        at its pose: :meth:`_ray_scores` (without the spread; ``own``, its own
        clusters) maximised by SciPy's Nelder-Mead over every parameter, clipped to
        its range, in at most ``RAY_REFIT_EVALS`` evaluations from a simplex
        ``RAY_REFIT_STEP`` of each range wide. Deterministic."""
        from scipy.optimize import minimize

        rng = _ranges(m)
        names = [n for n, (lo, hi) in rng.items() if hi > lo]
        if not names:
            return res
        lo = np.array([rng[n][0] for n in names])
        hi = np.array([rng[n][1] for n in names])
        x0 = np.clip([float(res.params[n]) for n in names], lo, hi)
        pose = [(np.asarray(res.rotation, dtype=float), np.asarray(res.translation,
                                                                    dtype=float))]

        def params_at(x: np.ndarray) -> dict:
            return {**res.params, **dict(zip(names, np.clip(x, lo, hi).tolist()))}

        def cost(x: np.ndarray) -> float:
            return -float(self._ray_scores(m, params_at(x), pose, rays, own)[0])

        simplex = np.vstack([x0, x0 + np.diag(RAY_REFIT_STEP * (hi - lo))])
        best = minimize(cost, x0, method="Nelder-Mead",
                        options={"maxfev": RAY_REFIT_EVALS, "initial_simplex": simplex})
        if not best.fun < cost(x0):
            return res
        return dataclasses.replace(res, params=params_at(best.x))

    @staticmethod
    def _lead(angles: np.ndarray, s: np.ndarray, period: float, i: int) -> float:
        """How many explained points the turn ``i`` of the scores ``s`` ``(Y,)`` at
        ``angles`` ``(Y,)`` (radians, over one ``period``) leads every turn
        ``SETTLED_APART`` degrees or more from it by (inf: there is none)."""
        gap = np.abs(angles - angles[i]) % period
        apart = np.minimum(gap, period - gap) >= math.radians(SETTLED_APART) - 1e-9
        if not apart.any():
            return math.inf
        return float(s[i] - s[apart].max()) / GAIN_CAP_LOG

    def turn_settled(self, det: Detection) -> bool:
        """Whether the scan settles the turn of ``det`` about the support's normal
        (:attr:`Detection.settled`), as it stands; only with a viewpoint. A model
        whose turn is not in doubt is unsettled only when its half turn ties with its
        own (:meth:`_half_turn_tied`). With no support, see :meth:`_settle_alone`.
        For a model whose turn is in doubt (:meth:`_doubt`: a turn, not a symmetry,
        moves under ``YAW_DOUBT`` of its surface), only with a support and upright
        search: its turns ``SETTLE_STEP`` degrees apart over one period of its
        symmetry are ray-cast without the spread at its own parameters
        (:meth:`_settle_scores`), and it is settled when its own turn scores
        ``SETTLED_PLAIN_RAYS`` explained points more than every turn
        ``SETTLED_APART`` degrees or more away. (Rays see a thin part that the points'
        distances, blurred by the noise in every direction, do not;
        cast at steps finer than the part's width seen from the axis they find its
        peak, which coarser steps fall either side of.)

        Scored as when :func:`_search` found it: its own inliers count as unclaimed (a
        point of its own clusters floating in front of a turn counts against that
        turn)."""
        return self._settle(det, turn=False)

    def _half_turn_tied(self, det: Detection) -> bool:
        """Whether the scan does not prefer ``det``'s turn to its half turn: its model's
        turn is not in doubt (:meth:`_doubt`), its half turn is not a symmetry, and its
        rays cast without the spread (:meth:`_ray_scores`, its own inliers unclaimed)
        do not score its turn more than ``HALF_TURN_TIE`` explained points above its
        half turn about the support's normal (a tie, or the half turn better: over
        the benchmark's seeds 720-1119, 2 of 340 settled bookshelves, one of them
        turned wrong). False without a viewpoint or rays."""
        if HALF_TURN_TIE is None or self.vp is None or det.fit is None:
            return False
        m = next(mm for mm in self.models if mm.name == det.model)
        full, sym, doubt = self._doubt(m)
        if doubt or sym[int(np.argmin(np.abs(full - math.pi)))]:
            return False
        rays = self._ray_set(m, det.fit)
        if len(rays) == 0:
            return False
        res = det.fit
        with self._unclaimed(det.inliers):
            s = self._ray_scores(m, dict(res.params),
                                 self._turned_in_place(res, np.array([0.0, math.pi])),
                                 rays, self._own_clusters(det.inliers))
        return float(s[0] - s[1]) <= HALF_TURN_TIE * GAIN_CAP_LOG

    def _alone(self, det: Detection) -> tuple | None:
        """``(model, rays (K,), own clusters (L,), turns (Y,) radians, period, lead
        needed)`` that judge the turn of ``det`` about its own z axis in a scan with
        no support (or with upright search off), where no earlier step chose its turn
        from the rays: its turns ``RAY_STEP`` degrees apart over one period of its
        symmetry, and the lead its turn needs (``SETTLED_PLAIN_RAYS`` explained points
        for a model whose turn is in doubt, else ``HALF_TURN_TIE``). None with a
        support and upright search, without a viewpoint or rays, or for a model that
        every turn leaves the same."""
        if (HALF_TURN_TIE is None or self.vp is None or det.fit is None
                or (self.plane is not None and self.upright)):
            return None
        m = next(mm for mm in self.models if mm.name == det.model)
        doubt = self._doubt(m)[2]
        turns, period = self._period_turns(m)
        if len(turns) < 2:
            return None
        rays = self._ray_set(m, det.fit)
        if len(rays) == 0:
            return None
        need = SETTLED_PLAIN_RAYS if doubt else HALF_TURN_TIE
        return m, rays, self._own_clusters(det.inliers), turns, period, need

    def _settle_alone(self, det: Detection, alone: tuple, turn: bool) -> bool:
        """Whether the scan settles the turn of ``det`` about its own z axis, with no
        support (``alone``: :meth:`_alone`'s answer for it): its turns are ray-cast
        without the spread at its own parameters (its own inliers unclaimed), and it
        is settled when its turn leads every turn ``SETTLED_APART`` degrees or more
        away by the lead needed. With
        ``turn``, it is first turned (in place: pose and fit) to the best turn when
        that scores more than the lead needed above its own (a lamp scanned on its
        own without noise was fitted 30 degrees off, and its rays preferred the true
        turn by 20 points)."""
        m, rays, own, turns, period, need = alone
        res = det.fit
        with self._unclaimed(det.inliers):
            s = self._ray_scores(m, dict(res.params), self._turned_in_place(res, turns),
                                 rays, own)
        i = int(np.argmax(s))
        if not turn or s[i] - s[0] <= need * GAIN_CAP_LOG:
            i = 0
        else:  # (i is not 0: the best leads its own turn)
            res = self._turned_by(res, turns[i])
            det.fit = res
            det.pose = Pose(res.rotation, res.translation)
        return self._lead(turns, s, period, i) >= need

    def settle_turn(self, det: Detection) -> bool:
        """The last step for a detection ``det``. With no support, :meth:`_settle_alone`
        (turning it). When its turn is not in doubt, returns whether its half turn
        does not tie with it (:meth:`_half_turn_tied`) and changes nothing. When its
        turn is in doubt: its turns
        ``SETTLE_STEP`` degrees apart are scored by its rays (:meth:`_settle_scores`),
        its parameters refitted to its rays at the best (:meth:`_ray_refit`) when that
        leads by under ``RAY_REFIT_BELOW`` explained points, its turns scored again at
        those, and it is turned to the best (in place: its
        pose, parameters and fit). Returns whether the scan settles that turn
        (:meth:`turn_settled`'s test). Its inliers and score stand: the refit moves
        its surface by a few millimetres, and the turn under ``YAW_DOUBT`` of it."""
        return self._settle(det, turn=True)

    def _settle(self, det: Detection, turn: bool) -> bool:
        """:meth:`settle_turn` (``turn``: judge and turn) or :meth:`turn_settled`
        (judge only): the one choice of test for ``det`` (with no support, in doubt,
        or neither) that both make."""
        alone = self._alone(det)
        if alone is not None:
            return self._settle_alone(det, alone, turn=turn)
        got = self._settle_rays(det)
        if got is None:
            return not self._half_turn_tied(det)
        m, rays, own, period = got
        res = det.fit
        with self._unclaimed(det.inliers):
            angles, s = self._settle_scores(m, res, rays, own, period)
            if not turn:
                return self._lead(angles, s, period, 0) >= SETTLED_PLAIN_RAYS
            i = int(np.argmax(s))
            if RAY_REFIT_EVALS > 0 and self._lead(angles, s, period, i) < RAY_REFIT_BELOW:
                best = self._turned_by(res, angles[i])
                refit = self._ray_refit(m, best, rays, own)
                if refit is not best:
                    res = dataclasses.replace(res, params=refit.params)
                    angles, s = self._settle_scores(m, res, rays, own, period)
        i = int(np.argmax(s))  # the first of equals: its own turn when it ties
        if i != 0:
            res = self._turned_by(res, angles[i])
        if res is not det.fit:
            det.fit = res
            det.params = dict(res.params)
            det.pose = Pose(res.rotation, res.translation)
        return self._lead(angles, s, period, i) >= SETTLED_PLAIN_RAYS

    @contextlib.contextmanager
    def _unclaimed(self, idx: np.ndarray):
        """Within the block, the points ``idx`` count as unclaimed; their claims are
        restored after."""
        was = self.claimed[idx].copy()
        self.claimed[idx] = False
        try:
            yield
        finally:
            self.claimed[idx] = was

    def _point_gains(self, m: _Model, params: dict, poses: list, idx: np.ndarray
                     ) -> np.ndarray:
        """``(H,)`` the summed :func:`_gain` of the scan points ``idx`` ``(K,)`` at
        their unsigned distances from ``m`` at ``params`` in each pose ``(R, t)``."""
        fld = m.fld.replace(params=params, check_ranges=False)
        q = np.concatenate([(self.P[idx] - t) @ R for R, t in poses])
        d = np.abs(np.asarray(fld.value(q), dtype=float)).reshape(len(poses), len(idx))
        return _gain(d, self.sigma).sum(axis=1)

    def _sphere(self, m: _Model, res: FitResult) -> tuple[np.ndarray, float]:
        """``(centre (3,), radius)``: the bounding sphere of the fit ``res`` of ``m``
        about the centre of its surface samples' box (scene frame), widened by three
        noise levels."""
        surf, _ = self._surface_at(m, res.params)
        mid = 0.5 * (surf.min(axis=0) + surf.max(axis=0))
        rad = float(np.linalg.norm(surf - mid, axis=1).max()) + 3.0 * self.sigma
        return res.pose.apply(mid[None])[0], rad

    def left_pieces(self, idx: np.ndarray, found: list[Detection]) -> list[np.ndarray]:
        """The connected pieces (the scan's neighbour links, as the clusters were
        made) of the points ``idx`` ``(K,)`` with at least ``LEFT_PIECE`` times
        ``min_points`` points each, largest first, that do not lie mostly within three
        noise levels of a detection of ``found``: what a cluster's detections left of
        it that may be an object of its own, not the surface of one of them left
        unclaimed (the rim of a 2.1 m table's top, 283 points beyond the reach its
        inliers are gathered from, was fitted as a second, smaller table)."""
        if LEFT_PIECE is None or len(idx) < LEFT_PIECE * self.mp:
            return []
        mask = np.zeros(len(self.P), dtype=bool)
        mask[idx] = True
        lab = components(self.nb, mask, linked_edges(self.nb, strict=True))[idx]
        sizes = np.bincount(lab)
        models = {m.name: m for m in self.models}
        fields = [as_field(d.shape, d.params, pose=d.pose, backend=models[d.model].backend,
                           what="detect", check_ranges=False) for d in found]
        out = []
        for i in np.flatnonzero(sizes >= LEFT_PIECE * self.mp):
            piece = idx[lab == i]
            if not any(np.mean(np.abs(np.asarray(f.value(self.P[piece]), dtype=float))
                               <= 3.0 * self.sigma) > 0.5 for f in fields):
                out.append(piece)
        return out

    def best_in_parts(self, idx: np.ndarray) -> Detection | None:
        """When no model explains the points ``idx`` as one object, the band test
        rejected a fit that explained many of them (two objects side by side, which
        one model stretched to its range limits covers best) and their footprint on
        the support is wider than some model's: :meth:`best_for` of each half of a
        2-means split of the footprint, the larger first, the other half's points
        counted as another object's in the front test (:meth:`_ray_evidence`); the
        first detection found, or None. With :data:`PARTS_WHEN_UNFIT`, also when
        models were fitted to the points and none passed; and when the points span
        more than any model may (:data:`SIZE_SLACK`), so that none was fitted: a table
        and a bookshelf behind it, touching in the scan, made one cluster 3.0 m
        across, and neither was found (benchmark scene 920)."""
        if self.plane is None or not self.upright or len(idx) < 2 * self.mp or \
                not (self.band_rejected or self.too_wide
                     or (PARTS_WHEN_UNFIT and self.unfit)):
            return None
        nrm, off = self.plane
        Q = self.P[idx]
        F = Q - np.outer(Q @ nrm - off, nrm)
        c0 = F.mean(axis=0)
        reach = float(np.linalg.norm(F - c0, axis=1).max())
        if reach <= FEET_REACH * min(m.foot for m in self.models):
            return None
        lab = _two_means(F)
        parts = sorted(((idx[lab == j], idx[lab != j]) for j in (0, 1)),
                       key=lambda a: -len(a[0]))
        for part, other in parts:
            if len(part) >= self.mp:
                self.foreign = np.zeros(len(self.P), dtype=bool)
                self.foreign[other] = True
                try:
                    det = self.best_for(part)
                finally:
                    self.foreign = None
                if det is not None:
                    return det
        return None

    def _standing(self) -> tuple[np.ndarray, float]:
        """``(normal (3,), offset)`` of the plane the current hypotheses stand on: the
        support's, raised by :attr:`lift` along its normal (scene units)."""
        nrm, off = self.plane
        return nrm, off + self.lift

    def best_lifted(self, idx: np.ndarray) -> Detection | None:
        """When no model standing on the support explains the points ``idx`` of one
        cluster and they lie over ``LIFT_MIN`` noise levels above it: :meth:`best_for`
        with the models standing on a surface under them instead
        (:meth:`_surfaces_under`: a lamp on a table, whose top the table's detection
        holds): the lowest of those surfaces on which a detection passes, or None.
        The highest surface under a lamp's shade is often the top of its own base,
        2.5 cm above the table, where a lamp fitted 2.5 cm high passes too (on a
        stool's seat it also explained more points there). Tried only after the
        support failed, so an object whose lower part an occluder hides (a chair
        behind a table, its top under the chair's footprint) is placed on the
        support as before."""
        if self.plane is None or not self.upright or not LIFT:
            return None
        for lift in self._surfaces_under(idx)[::-1]:
            self.lift = lift
            try:
                det = self.best_for(idx)
            finally:
                self.lift = 0.0
            if det is not None:
                return det
        return None

    def _surfaces_under(self, idx: np.ndarray) -> list[float]:
        """The heights above the support (scene units, highest first, at most
        ``LIFT_LEVELS``) of the surfaces facing up under the points ``idx``: runs of
        ``3 sigma`` bins of the heights of other points off the support, each bin
        holding at least ``LIFT_POINTS``, of points whose normals lie within
        ``LIFT_TILT`` degrees of the support's, below the cluster's lowest points (its
        first percentile) and over ``LIFT_MIN`` noise levels above the support, inside
        the cluster's footprint (within its largest distance from its median, along
        the support); each level the median height of its run. Empty when the
        cluster's lowest points lie within ``LIFT_MIN`` noise levels of the
        support."""
        nrm, off = self.plane
        h = self.P @ nrm - off
        low = float(np.percentile(h[idx], 1.0))
        floor = LIFT_MIN * self.sigma
        if low <= floor:
            return []
        uv = self.P @ frame_z(nrm)[:, :2]
        c = np.median(uv[idx], axis=0)
        reach = float(np.linalg.norm(uv[idx] - c, axis=1).max())
        under = np.ones(len(self.P), dtype=bool)
        under[idx] = False
        under &= ~self.support & (h > floor) & (h < low - 3.0 * self.sigma)
        under &= np.abs(self.N @ nrm) >= math.cos(math.radians(LIFT_TILT))
        under &= np.linalg.norm(uv - c, axis=1) <= reach
        hs = h[under]
        if len(hs) < LIFT_POINTS:
            return []
        width = 3.0 * self.sigma
        b = np.floor((hs - floor) / width).astype(np.int64)
        counts = np.bincount(b)
        full = counts >= LIFT_POINTS
        levels = []
        k = len(counts) - 1
        while k >= 0 and len(levels) < LIFT_LEVELS:
            if not full[k]:
                k -= 1
                continue
            j = k
            while j - 1 >= 0 and full[j - 1]:
                j -= 1
            levels.append(float(np.median(hs[(b >= j) & (b <= k)])))
            k = j - 1
        return levels

    def best_joined(self, idx: np.ndarray, single: Detection | None
                    ) -> Detection | None:
        """Without upright hypotheses (no support, or ``upright=False``): the points
        ``idx`` of one cluster joined by the free points of the nearest other clusters
        (nearest first, by their closest points) while the whole fits within some
        model's size (:data:`SIZE_SLACK`) and each cluster joined lies within
        ``JOIN_GAP`` of the largest model's diameter, and :meth:`best_for` of the
        whole; its detection replaces ``single`` (the detection on ``idx`` alone, or
        None) when it claims ``min_points`` more points. Returns ``single`` when no
        cluster joins or the joined fit fails. A lamp scanned on its own shows as two
        clusters, its shade and its stem with the base (the thin spokes between them
        hardly seen), and the multistart fit of either alone fails; a table at 1 cm
        noise as four, its top and legs, and its top alone fits a table 5 cm too
        high (which passes, so the joined fit competes with it rather than follow
        its failure: joined after, the legs were fitted as a second table). On a
        support the upright hypotheses gather such pieces themselves
        (:meth:`_gather`)."""
        if (self.plane is not None and self.upright) or not JOIN_CLUSTERS:
            return single
        from scipy.spatial import cKDTree

        limit = max(2.0 * m.radius * SIZE_SLACK for m in self.models) + 6.0 * self.sigma
        tree = cKDTree(self.P[self._subsample(idx, JOIN_POINTS)])
        own = np.unique(self.label[idx])
        free = np.flatnonzero((self.label >= 0) & ~self.claimed
                              & ~np.isin(self.label, own))
        labs, counts = np.unique(self.label[free], return_counts=True)
        order = free[np.argsort(self.label[free], kind="stable")]
        gaps = []
        for c, k, n in zip(labs, np.cumsum(counts) - counts, counts):
            if n < self.mp:
                continue
            pts = order[k:k + n]  # ascending: a stable sort of ascending indices
            gap = float(tree.query(self.P[self._subsample(pts, JOIN_POINTS)])[0].min())
            if gap <= JOIN_GAP * limit / SIZE_SLACK:
                gaps.append((gap, c, pts))
        joined = idx
        for _gap, _c, pts in sorted(gaps, key=lambda g: (g[0], g[1])):
            both = np.union1d(joined, pts)
            if _span(self.P[both]) <= limit:
                joined = both
        if len(joined) == len(idx):
            return single
        det = self.best_for(joined)
        if det is None or (single is not None and
                           len(det.inliers) < len(single.inliers) + self.mp):
            return single
        return det

    def _own_clusters(self, inl: np.ndarray) -> np.ndarray:
        """``(L,)`` the labels of the clusters holding at least a tenth of a fit's
        inliers ``inl`` ``(K,)`` (point indices): the fit's own clusters."""
        labs, counts = np.unique(self.label[inl], return_counts=True)
        return labs[(labs >= 0) & (counts >= 0.1 * max(len(inl), 1))]

    def _subsample(self, idx: np.ndarray, k: int) -> np.ndarray:
        """``idx`` ``(M,)`` (sorted point indices) when ``M <= k``, else the ``k`` of them
        with the lowest priorities, sorted: a seeded uniform random subsample that
        depends only on the set (equal sets give equal subsamples, whatever the run
        did before)."""
        if len(idx) <= k:
            return idx
        return np.sort(idx[np.argpartition(self.priority[idx], k - 1)[:k]])

    def _surface_at(self, m: _Model, params: dict) -> tuple[np.ndarray, np.ndarray]:
        """The model's surface samples ``(K, 3)`` and their unit normals ``(K, 3)`` moved
        onto the model at ``params`` (one projection step along the gradient; model
        frame)."""
        return _moved_surface(m.fld, m.surface, params)

    def _ray_index(self) -> tuple[RayIndex, np.ndarray]:
        """``(index, ranges)``: the scan's unit ray directions for nearest-ray queries
        within the tolerance of a ray match (:class:`.rays.RayIndex`; its ``tol``, in
        radians as a chord: 1.5 times the median angle to the nearest other ray, not
        counting near-copies: :func:`csdf.points.sample_spacing`) and
        the points' ranges ``(N,)`` from the viewpoint (scene units); built once."""
        if getattr(self, "_rays", None) is None:
            from scipy.spatial import cKDTree

            tree = cKDTree(self.dirs)
            step = max(1, len(self.dirs) // 2000)
            tol = 1.5 * sample_spacing(tree, self.dirs[::step])
            self._rays = (RayIndex(self.dirs, tol, tree),
                          np.linalg.norm(self.P - self.vp, axis=1))
        return self._rays

    def _yaw_scan(self, m: _Model, R: np.ndarray, t: np.ndarray, params: dict
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The explained mass of model ``m`` at ``params`` turned about the support's
        normal through its centre by each of ``YAW_STEPS`` yaws from the pose ``(R, t)``:
        ``(angles (Y,) radians, scores (Y,), centre (3,))``. A score is the summed
        :func:`_gain` of the free points near the model (a fixed seeded subsample of at
        most ``SCAN_POINTS``), less, with a viewpoint, that sum's whole scale
        (``GAIN_CAP`` per point) times the fraction of the model's sensor-facing surface
        samples that the sensor saw through (a scan point on their ray lies farther by
        over three noise levels)."""
        nrm = self.plane[0]
        surf, sn = self._surface_at(m, params)
        lo, hi = surf.min(axis=0), surf.max(axis=0)
        cm = 0.5 * (lo + hi)
        cw = R @ cm + t
        rad = float(np.linalg.norm(surf - cm, axis=1).max())
        near = np.flatnonzero(~self.claimed & ~self.support & (
            np.linalg.norm(self.P - cw, axis=1) <= 1.1 * rad + 3 * self.sigma))
        near = self._subsample(near, SCAN_POINTS)
        angles = 2.0 * math.pi * np.arange(YAW_STEPS) / YAW_STEPS
        poses = []
        for th in angles:
            Rt = _yaw_matrix(nrm, th)
            poses.append((Rt @ R, Rt @ (t - cw) + cw))
        score = self._point_gains(m, params, poses, near)
        if self.vp is not None and len(near):
            rays, rng_scan = self._ray_index()
            Xw = np.stack([surf @ RR.T + tt for RR, tt in poses])  # (Y, K, 3)
            Nw = np.stack([sn @ RR.T for RR, _ in poses])
            v = Xw - self.vp
            r = np.linalg.norm(v, axis=2)
            front = np.einsum("yki,yki->yk", Nw, -v) > 0
            dd, j = rays.nearest((v / r[..., None]).reshape(-1, 3))
            hit = np.isfinite(dd).reshape(r.shape) & front
            jj = np.minimum(j, len(self.P) - 1).reshape(r.shape)
            through = hit & (rng_scan[jj] > r + 3.0 * self.sigma)
            frac = through.sum(axis=1) / np.maximum(hit.sum(axis=1), 1)
            score = score - frac * GAIN_CAP_LOG * len(near)
        return angles, score, cw

    def _turns(self, m: _Model, idx: np.ndarray, base: FitResult, found: list,
               refits: int) -> list:
        """``found`` with the fits that pass verification (items ``(explained mass,
        score, result, inliers, checked)``) from ``base`` turned about the support's
        normal to the ``refits`` best yaws of :meth:`_yaw_scan` (local maxima at least
        ``YAW_SAME`` degrees from ``base``'s own yaw and from each other; equal scores,
        the model's own symmetries, count once). A single view often leaves a box-like
        object's front and back, or its sides, nearly alike, and the turn of a nearly
        symmetric one (a lamp's spokes) rests on a few points: the screen's pick among
        them is a close call."""
        nrm = self.plane[0]
        angles, score, cw = self._yaw_scan(m, base.rotation, base.translation,
                                           dict(base.params))
        n = len(angles)
        peaks = [i for i in range(n) if score[i] >= score[(i - 1) % n]
                 and score[i] >= score[(i + 1) % n]]
        peaks.sort(key=lambda i: (-score[i], i))
        same = math.radians(YAW_SAME)
        chosen: list[int] = []
        for i in peaks:
            a = angles[i]
            if min(a, 2 * math.pi - a) < same:
                continue
            if any(min(abs(a - angles[j]), 2 * math.pi - abs(a - angles[j])) < same
                   or abs(score[i] - score[j]) <= 1e-9 * max(abs(score[j]), 1.0)
                   for j in chosen):
                continue
            chosen.append(i)
            if len(chosen) >= refits:
                break
        for i in chosen:
            Rt = _yaw_matrix(nrm, float(angles[i]))
            init = {"rotation": Rt @ base.rotation,
                    "translation": Rt @ (base.translation - cw) + cw,
                    "params": dict(base.params)}
            self._add_verified(m, idx, init, found, stand=True, shrink=SHRINK_TURNS)
        if SWAP_TURNS:
            self._swapped(m, idx, base, found)
        return found

    def _swapped(self, m: _Model, idx: np.ndarray, base: FitResult, found: list) -> None:
        """When ``m`` has a width and a depth parameter (:func:`_extents`) and the fit
        ``base`` holds one of them at its bound, ``base`` refitted a quarter turn either
        way about the support's normal through its centre, with the width set to give
        the extent its depth gave and the depth the extent its width gave (clipped to
        their ranges); appends the refits that pass verification to ``found`` (items
        as :meth:`_turns`'), where explained mass judges them against the rest. A
        bookshelf seen from the side was fitted to it as its front, a quarter turn off,
        its width and depth both at their bounds."""
        at = [n for n, _, _ in _at_bound(m, base.params)]
        ext = _extents(m, at) if at else None
        if ext is None:
            return
        px, py, sx, sy = ext
        if not set(at) & {px, py}:
            return
        surf, _ = self._surface_at(m, base.params)
        lo, hi = surf.min(axis=0), surf.max(axis=0)
        size = hi - lo
        rng = _ranges(m)
        pv = dict(base.params)
        _resize(pv, px, size[1] - size[0], sx, rng)
        _resize(pv, py, size[0] - size[1], sy, rng)
        cw = base.rotation @ (0.5 * (lo + hi)) + base.translation
        for th in (0.5 * math.pi, -0.5 * math.pi):
            Rt = _yaw_matrix(self.plane[0], th)
            init = {"rotation": Rt @ base.rotation,
                    "translation": Rt @ (base.translation - cw) + cw, "params": pv}
            self._add_verified(m, idx, init, found, stand=True)

    def _explains_most(self, inl: np.ndarray, idx: np.ndarray) -> bool:
        """Whether a fit whose inliers are ``inl`` ``(K,)`` explains most of the points
        ``idx`` (``RETRY_EXPLAINED`` of them, and at least the minimum support): a fit
        that failed verification but is worth holding back or starting again."""
        return len(inl) >= max(self.mp, RETRY_EXPLAINED * len(idx))

    def _add_verified(self, m: _Model, idx: np.ndarray, start: dict, found: list,
                      shrink: bool = False, **kw: Any) -> None:
        """Fits ``m`` to the points ``idx`` from ``start`` (:meth:`_candidate`, with its
        keywords ``kw``) and appends the fit to ``found`` as ``(explained mass, score,
        result, inliers, checked)`` when it passes verification; with ``shrink``, a fit
        that fails with a parameter at an end of its range and explains most of the
        points (``RETRY_EXPLAINED``, as a screened fit must to be retried) is held back
        to the defaults (:meth:`_shrunk`'s last step)."""
        r = self._candidate(m, idx, start, **kw)
        if r is not None:
            ok, sc, il, ch, gain = self._verify(m, r)
            if ok:
                found.append((gain, sc, r, il, ch))
            elif shrink and self._explains_most(il, idx):
                self._shrunk(m, idx, r, found, steps=SHRINK_STEPS[-1:])


def _swaps(m: _Model) -> list[tuple[str, str, float]]:
    """The pairs of parameters of ``m`` that a quarter turn about its z axis exchanges:
    ``(a, b, turn)`` each (``turn`` in radians, +-pi/2), where the model at values
    ``a = u, b = v`` is the model at ``a = v, b = u`` turned by ``turn``, to within
    ``1e-6`` of its radius on ``SURFACE_SAMPLES`` points of its box (tested at two
    pairs of values inside both ranges; pairs whose ranges do not meet are not
    tried). Found once per model."""
    if m.swaps is not None:
        return m.swaps
    m.swaps = []
    ps = [p for p in m.fld.program.params if math.isfinite(p.lo) and math.isfinite(p.hi)]
    rng = np.random.default_rng(0)
    lo, hi = m.bounds
    pad = 0.25 * (hi - lo) + 0.05 * m.radius
    q = rng.uniform(lo - pad, hi + pad, (SURFACE_SAMPLES, 3))
    defaults = _defaults(m)
    for i, pa in enumerate(ps):
        for pb in ps[i + 1:]:
            olo, ohi = max(pa.lo, pb.lo), min(pa.hi, pb.hi)
            if not ohi > olo:
                continue
            u, v = olo + 0.3 * (ohi - olo), olo + 0.8 * (ohi - olo)
            for turn in (0.5 * math.pi, -0.5 * math.pi):
                ok = True
                for x, y in ((u, v), (v, u)):
                    f1 = m.fld.replace(params={**defaults, pa.name: x, pb.name: y},
                                       check_ranges=False).value(q)
                    f2 = m.fld.replace(params={**defaults, pa.name: y, pb.name: x},
                                       check_ranges=False).value(q @ _rz(turn))
                    if not np.all(np.abs(np.asarray(f1) - np.asarray(f2))
                                  <= 1e-6 * m.radius):
                        ok = False
                        break
                if ok:
                    m.swaps.append((pa.name, pb.name, turn))
                    break
    return m.swaps


def _canonical(m: _Model, res: FitResult | None) -> FitResult | None:
    """The fit ``res`` of ``m`` (None passes through), or the same surface with each
    exchangeable pair of its parameters (:func:`_swaps`) exchanged and its model
    turned to match, when both exchanged values lie inside their ranges and nearer
    their defaults (summed distances, each over its range's span)."""
    if res is None or not _swaps(m):
        return res
    rng = _ranges(m)
    defaults = _defaults(m)

    def far(name: str, v: float) -> float:
        return abs(v - defaults[name]) / (rng[name][1] - rng[name][0])

    out = res
    for a, b, turn in _swaps(m):
        va, vb = float(out.params[a]), float(out.params[b])
        if far(a, vb) + far(b, va) < far(a, va) + far(b, vb):
            out = _exchanged(m, out, a, b, turn) or out
    return out


def _exchanged(m: _Model, res: FitResult, a: str, b: str, turn: float
               ) -> FitResult | None:
    """The fit ``res`` of ``m`` with its parameters ``a`` and ``b`` exchanged and its
    model turned by ``turn`` (radians, about its z axis) to match: the same surface
    when ``(a, b, turn)`` is one of :func:`_swaps`; None when an exchanged value lies
    outside its range."""
    rng = _ranges(m)
    va, vb = float(res.params[a]), float(res.params[b])
    if not (rng[a][0] <= vb <= rng[a][1] and rng[b][0] <= va <= rng[b][1]):
        return None
    return dataclasses.replace(res, rotation=np.asarray(res.rotation, dtype=float)
                               @ _rz(turn), params=dict(res.params, **{a: vb, b: va}))


def _in_box(W: np.ndarray, pose: Pose, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """``(K,)`` which of the points ``W`` ``(K, 3)`` (scene frame) lie in the box
    ``[lo, hi]`` (each ``(3,)``) of a model's frame placed by ``pose``."""
    u = pose.apply_inverse(W)
    return np.all((u >= lo) & (u <= hi), axis=1)


def _traded_too(m: _Model, fits: list[FitResult]) -> list[FitResult]:
    """``fits`` of ``m``, then each with every pair of its exchangeable sizes traded
    (:func:`_swaps`, :func:`_exchanged`; a trade whose values leave their ranges is
    left out)."""
    return list(fits) + [e for f in fits for x, y, turn in _swaps(m)
                         if (e := _exchanged(m, f, x, y, turn)) is not None]


def _defaults(m: _Model) -> dict[str, float]:
    """Each parameter's default of model ``m``: ``{name: value}``."""
    return {p.name: float(p.default) for p in m.fld.program.params}


def _ranges(m: _Model) -> dict[str, tuple[float, float]]:
    """Each parameter's range of model ``m``: ``{name: (lo, hi)}``."""
    return {p.name: (float(p.lo), float(p.hi)) for p in m.fld.program.params}


def _resize(pv: dict, name: str, change: float, slope: float,
            rng: dict[str, tuple[float, float]]) -> None:
    """Sets the size parameter ``name`` of the values ``pv`` (in place) to change its
    extent by ``change`` (m), at ``slope`` metres of extent per unit of the parameter,
    clipped to its range in ``rng`` (:func:`_ranges`)."""
    pv[name] = float(np.clip(pv[name] + change / slope, *rng[name]))


def _sizes_inside(m: _Model, found: list, names: tuple[str, ...]) -> list:
    """The items of ``found`` (fits of ``m``, as :meth:`_Run._turns`') none of whose
    parameters ``names`` lies at an end of its range (:func:`_at_bound`)."""
    return [f for f in found
            if not set(names) & {n for n, _, _ in _at_bound(m, f[2].params)}]


def _at_bound(m: _Model, params: dict) -> list[tuple[str, float, float]]:
    """The parameters of ``m`` whose values in ``params`` lie within ``AT_BOUND`` of
    its span from an end of their range that their default is not at: ``(name, that
    end, default)`` each (a size the fit pushed until the range stopped it)."""
    out = []
    for p in m.fld.program.params:
        v, lo, hi = float(params[p.name]), float(p.lo), float(p.hi)
        span = hi - lo
        if not (math.isfinite(span) and span > 0):
            continue
        end = hi if v >= hi - AT_BOUND * span else lo if v <= lo + AT_BOUND * span \
            else None
        if end is not None and abs(float(p.default) - end) > AT_BOUND * span:
            out.append((p.name, end, float(p.default)))
    return out


def _band_fraction(d: np.ndarray, lab: np.ndarray, off: np.ndarray, sigma: float,
                   mp: int) -> float:
    """The band test's figure: of the points of a fit's own clusters within ``BAND``
    noise levels of its surface, the fraction within three (1.0 when there are none).

    Args:
        d: ``(K,)`` unsigned distances of the free points near the fit to its surface
            (scene units).
        lab: ``(K,)`` their cluster labels (-1: none).
        off: ``(K,)`` which of them are off the support.
        sigma: the noise level (scene units).
        mp: the fewest points a detection explains; a cluster is the fit's own when it
            holds at least ``max(mp, 10 %)`` of the fit's close points (a neighbour that
            only reaches into the band is not).
    """
    close = d <= 3.0 * sigma
    labs, counts = np.unique(lab[off & close & (lab >= 0)], return_counts=True)
    own = np.isin(lab, labs[counts >= max(mp, 0.1 * counts.sum())]) & off
    band = np.count_nonzero(own & (d <= BAND * sigma))
    return np.count_nonzero(own & close) / band if band else 1.0


#: the explained mass of a point at the cap (``log(1 + GAIN_CAP^2)``)
GAIN_CAP_LOG = math.log1p(GAIN_CAP ** 2)


def _gain(d: np.ndarray, sigma: float) -> np.ndarray:
    """The explained mass of points at unsigned distances ``d`` (any shape, scene units)
    from a model's surface, noise level ``sigma``: ``cap - min(log(1 + (d / sigma)^2),
    cap)`` with ``cap = log(1 + GAIN_CAP^2)`` (a Cauchy loss capped at ``GAIN_CAP`` noise
    levels): the cap for a point on the surface, zero from ``GAIN_CAP`` noise levels
    out. Summed over a fixed set of points it is a soft count of the points explained,
    sharper near the surface (same shape as ``d``)."""
    return GAIN_CAP_LOG - np.minimum(np.log1p((d / sigma) ** 2), GAIN_CAP_LOG)


def detections_to_scene(detections, scene=None):
    """A :class:`csdf.Scene` holding every detection (model, pose, parameters; named
    ``'{model}_{k}'``), added to ``scene`` when given.

    Raises:
        CsdfError: an item that is not a :class:`Detection` or :class:`PrimitiveDetection`.
    """
    from ..scene import Scene

    sc = Scene() if scene is None else scene
    count: dict[str, int] = {}
    for d in detections:
        if isinstance(d, Detection):
            k = count[d.model] = count.get(d.model, 0) + 1
            sc.add(d.source if d.source is not None else d.shape, pose=d.pose,
                   params=d.params, name=f"{d.model}_{k}")
        elif isinstance(d, PrimitiveDetection):
            if d.kind == "plane":
                continue  # unbounded: a scene holds bounded models
            k = count[d.kind] = count.get(d.kind, 0) + 1
            sc.add(d.shape, name=f"{d.kind}_{k}")
        else:
            raise CsdfError(f"detections_to_scene: expected Detection items, got "
                            f"{type(d).__name__}")
    return sc

