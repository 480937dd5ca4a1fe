"""The base of every settings model (`Settings`: frozen, unknown keys and non-finite numbers refused)
and `setting(...)`: a field's default, description, unit and bounds in one place, from which the
JSON schema, `pbmdem config --show-defaults` and the checks of a config file all come.
"""

from __future__ import annotations

from typing import Annotated, Any, TypeVar

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, StringConstraints, TypeAdapter, ValidationError

from .errors import ConfigError, describe_errors

#: the largest impeller speed a configuration or command line may give (rpm): the one owner of
#: the limit, through the type `Rpm` of every speed setting and `check_rpm`
RPM_MAX = 20000


def setting(default: Any = ..., description: str = "", unit: str | None = None, **bounds) -> Any:
    """A settings field: default (`...`: required), description, unit, and bounds (ge, gt, le,
    lt, min_length, max_length, pattern); a model default is given as the model class."""
    extra = {"unit": unit} if unit else None
    if isinstance(default, type) and issubclass(default, BaseModel):
        return Field(default_factory=default, description=description, json_schema_extra=extra, **bounds)
    return Field(default, description=description, json_schema_extra=extra, **bounds)


def _unique(values):
    if len(set(values)) != len(values):
        raise ValueError("has non-unique elements")
    return values


T = TypeVar("T")
#: a list of distinct values (JSON schema uniqueItems), e.g. Unique[float]
Unique = Annotated[tuple[T, ...], AfterValidator(_unique), Field(json_schema_extra={"uniqueItems": True})]
#: a plain name of a size distribution (letter first; letters, digits, '_' or '-'), also a deck's
NAME_PATTERN = r"^[A-Za-z][A-Za-z0-9_-]{0,63}$"
Name = Annotated[str, StringConstraints(pattern=NAME_PATTERN)]
#: a config key of a pbm setting, e.g. pbm.aggregation.beta0
PbmKey = Annotated[str, StringConstraints(pattern=r"^pbm(\.[a-z_0-9]+)+$")]
#: an impeller speed (rpm)
Rpm = Annotated[float, Field(gt=0, le=RPM_MAX)]


class Settings(BaseModel):
    """A frozen settings model: unknown keys refused, NaN and infinities refused."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False, validate_default=True)

    @classmethod
    def from_dict(cls, data: dict, key: str = ""):
        """The settings of the plain data `data` (a rule's params, a JSON file); ConfigError
        naming `key` and what is allowed otherwise."""
        try:
            return cls.model_validate(data)
        except ValidationError as exc:
            raise ConfigError("invalid settings:\n  " + "\n  ".join(describe_errors(exc, cls, key))) from None

    def to_dict(self) -> dict:
        """Plain data (dicts, lists, numbers, strings), for params and JSON."""
        return self.model_dump(mode="json")

    def replace(self, **changes):
        """A copy with `changes` (trusted values of the fields' types)."""
        return self.model_copy(update=changes)


_RPM = TypeAdapter(Rpm)


def check_rpm(rpm, key: str = "--rpm") -> float:
    """An impeller speed as a float, or ConfigError naming `key` and the value (0 < rpm <= RPM_MAX)."""
    try:
        return _RPM.validate_python(rpm)
    except ValidationError:
        raise ConfigError(
            f"{key} = {rpm!r}: impossible impeller speed (allowed: a finite number, 0 < rpm <= {RPM_MAX:g})"
        ) from None
