"""Model-error diagnosis: where the model fails, which physical effect is missing, add it.

>>> from analysis.diagnosis import compare, diagnose, augment        # doctest: +SKIP
>>> result = diagnose(model, data, linear_run="random.h5")             # doctest: +SKIP
>>> best = result.group[0]                                              # doctest: +SKIP
>>> values, known = best.start_values()                                 # doctest: +SKIP
>>> new = augment(model, data, best.candidate, values=values, known=known,
...               linear_run="random.h5", out="new.toml")               # doctest: +SKIP

Modules, in the order data flows:

branches
    :class:`BranchMatchedPredictor`: model FRFs on the branch the test was on (a jump the
    rig made early is not a model error), the compared orders (an order the test holds at
    zero force drives the model but is not compared), standard errors with the force's
    error carried through the model.
compare
    Normalised residuals, blocks by sensor/order/level/band with family-wise verdicts, maps.
signatures
    Evidence in the data that points at physics (resonance shift, normalised peak, growth
    exponents, distortion, linear misfit), in words with numbers.
candidates
    Laws of the element library at plausible locations, and linear changes; how each is
    written into a model file.
screen
    The harmonic-domain force estimate and least-squares law fits, ranked by BIC.
linear_screen
    Linear candidates (mass, spring, compliant joint) on the linear test.
refit
    Recalibration on the measured branch (several starts, Levenberg-Marquardt).
verify
    Candidates recalibrated in the full model (picklable jobs).
diagnose
    Compare, evidence, screen, verify, rank, verdict: :func:`diagnose`.
result
    The diagnosis' settings, ranking and verdict in words.
readout
    What the data show about a missing law no candidate explains: the describing function of
    the force at a location against the amplitude, read against the standard laws'.
discriminate
    The measurement that separates tied candidates (planning sweeps, prediction differences
    over the noise).
augment
    Add the chosen effect, recalibrate everything, before/after: :func:`augment`.
cli
    ``compare``, ``diagnose`` and ``augment`` commands.
"""

from analysis.diagnosis.augment import AugmentResult, augment
from analysis.diagnosis.candidates import Candidate, Law, Location, default_candidates
from analysis.diagnosis.compare import Block, Comparison, compare
from analysis.diagnosis.diagnose import diagnose
from analysis.diagnosis.linear_screen import LinearFit, linear_screen
from analysis.diagnosis.readout import ForceReadout, read_missing_force
from analysis.diagnosis.refit import Refit, refit
from analysis.diagnosis.result import Diagnosis, DiagnosisSettings, RankedCandidate
from analysis.diagnosis.screen import Screen, ScreenFit
from analysis.diagnosis.signatures import Evidence, Finding, find_signatures
from analysis.predict_branches import BranchMatchedPredictor

__all__ = [
    "AugmentResult",
    "Block",
    "BranchMatchedPredictor",
    "Candidate",
    "Comparison",
    "Diagnosis",
    "DiagnosisSettings",
    "Evidence",
    "Finding",
    "ForceReadout",
    "Law",
    "LinearFit",
    "Location",
    "RankedCandidate",
    "Refit",
    "Screen",
    "ScreenFit",
    "augment",
    "compare",
    "default_candidates",
    "diagnose",
    "find_signatures",
    "linear_screen",
    "read_missing_force",
    "refit",
]
