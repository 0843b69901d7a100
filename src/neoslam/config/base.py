"""The base of every configuration section: unknown fields, infinities and NaN are refused by name."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict

__all__ = ["Section"]


class Section(BaseModel):
    # allow_inf_nan=False: .inf or .nan in a YAML file or a NEOSLAM_* variable is refused with the field's name
    # (an infinite spacing or cell size validates as "> 0" and then breaks a run far from its cause).
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)
