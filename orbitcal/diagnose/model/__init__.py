"""The diagnosis as a model of the data (issue 43): a noise model, effects as groups of columns
with priors from the catalogue, exact posterior probabilities of every model of up to three
effects from one whitened Gram matrix, and one confirmation on a block no selection step saw.

:func:`model_diagnosis` runs it on prepared data; :func:`with_model_keys` writes its numbers into
a section-5 report (``probability``, ``verdict_probability``, ``confirmation``, ``model``).
"""

from orbitcal.diagnose.model.core import ModelDiagnosis, candidate_forms, model_diagnosis
from orbitcal.diagnose.model.report_keys import with_model_keys

__all__ = ["ModelDiagnosis", "candidate_forms", "model_diagnosis", "with_model_keys"]
