"""Pieces shared by the response models.

Two kinds of model, by who builds the dict they describe:

* :class:`ClosedModel`: a dict the route beside it builds. Extra keys are refused, so
  a key added to the route and not to its model fails the API tests (a 500 from
  FastAPI's response validation) instead of vanishing from every answer.
* :class:`OpenModel`: the JSON of a domain object (a ``to_json()`` of ``station``, a
  file read back, the runtime's status), which other code grows. Keys it adds pass
  through, described or not; the model documents the ones the API promises.

A field with a default (``None``) is one the dict leaves out in some answers (a list's
item has no characteristics, a silent drive no position): the routes that serve such
models answer with ``response_model_exclude_unset``, so a key absent from the dict is
absent from the answer, never turned into ``null``.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, ConfigDict, WithJsonSchema

#: a JSON number, passed on as given: pydantic's ``float`` would turn an integer (a
#: nominal of 12 in a TOML file, a table's target) into 12.0 in the answer
Number = Annotated[int | float, WithJsonSchema({"type": "number"})]

#: a time as the API writes it: ISO 8601 with its offset (kept as the string the
#: route made, so its form does not change)
IsoTime = Annotated[str, WithJsonSchema({"type": "string", "format": "date-time"})]

#: where to go next: relation name -> path of this API (``self``, ``qif``, ``proposal`` ...)
Links = dict[str, str]


class ClosedModel(BaseModel):
    """A dict the route builds: every key modelled, none other accepted."""

    model_config = ConfigDict(extra="forbid")


class OpenModel(BaseModel):
    """A domain object's JSON: the promised keys modelled, any other passed through."""

    model_config = ConfigDict(extra="allow")
