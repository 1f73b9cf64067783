"""Controller specs: each controller is one readable file (:mod:`.schema`) naming every stage
and constant, assembled by :func:`build` (:mod:`.build`), its files checked by hash
(:mod:`.files`). The shipped ones live in ``rabbit_policy/controllers``."""

from rabbit_policy.spec.build import build, load_controller, load_packaged
from rabbit_policy.spec.files import packaged_spec, packaged_spec_dir
from rabbit_policy.spec.schema import ControllerSpec, SpecError, dump_spec, load_spec, parse_spec

__all__ = ["ControllerSpec", "SpecError", "build", "dump_spec", "load_controller", "load_packaged", "load_spec",
           "packaged_spec", "packaged_spec_dir", "parse_spec"]
