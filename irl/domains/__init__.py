"""The paper's benchmark domains."""

from irl.domains.base import Domain
from irl.domains.onion_sorting import onion_sorting

__all__ = ["Domain", "onion_sorting"]
