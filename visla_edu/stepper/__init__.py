"""The filter stepper: step a filter forwards and backwards in time and watch it work.

Modules, from the model up: :mod:`~visla_edu.stepper.model` (:class:`Stepper`, re-exported here),
:mod:`~visla_edu.stepper.figure` (``StepperFigure``), :mod:`~visla_edu.stepper.widget` (``StepperWidget``, the
ipywidgets controls), :mod:`~visla_edu.stepper.app` (``serve``: the widget as a Voila page, ``visla-edu
stepper``). Importing this package loads neither matplotlib nor ipywidgets.
"""

from visla_edu.stepper.model import (MODE_LABELS, NOISE_FIELDS, SteppableFilter, Stepper, dataset_choices,
                                     world_position_covariance)

__all__ = ["MODE_LABELS", "NOISE_FIELDS", "SteppableFilter", "Stepper", "dataset_choices",
           "world_position_covariance"]
