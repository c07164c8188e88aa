"""Request and response models of the API (pydantic v2).

:mod:`service.schemas.base` holds :class:`~service.schemas.base.StrictModel`, the base of every
request body (``extra="forbid"``, strict types, finite numbers only), and the helpers that build
fields from :data:`physics.PARAMETERS`, so no parameter is ever listed by hand. Responses derive
from :class:`~service.schemas.base.ResponseModel`. Each resource keeps its models in its own module.
"""
