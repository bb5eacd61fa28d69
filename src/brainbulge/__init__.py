"""brainbulge: swelling brains and decompressive craniectomy by nonlinear finite elements.

Reproduces Weickenmeier, Saez, Goriely, Kuhl, "Bulging brains", J. Elasticity 129 (2017)
197-212: an elastically incompressible, swelling Mooney-Rivlin solid (mixed
displacement-pressure formulation, ``J = Js`` enforced by a Lagrange multiplier) pressed
against a rigid skull with an opening.

Importing the package changes nothing in the process (environment, allocator, ``PATH``);
the process-wide tuning of a run is :func:`brainbulge.runtime.configure`, which the command
line and the one-call API (:func:`hemidisk`, :func:`brain`, :func:`study`,
:mod:`brainbulge.api`, loaded on first use) call.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("brainbulge")
except PackageNotFoundError:  # running from a source tree without installation
    __version__ = "0.0.0+unknown"

from brainbulge.lazy import lazy_names

__all__ = ["__version__", "hemidisk", "brain", "study", "Result"]
__getattr__, __dir__ = lazy_names(__name__, globals(), {
    "hemidisk": "api", "brain": "api", "study": "api", "Result": "api"})
