"""The API's response models: what every JSON route answers, for ``/openapi.json``.

One module per router of :mod:`api.routes` (request bodies stay beside the route that
reads them). The models describe dicts the routes and the domain build; FastAPI
validates each answer through its model, so a key the model lacks would vanish from
the answer: :mod:`api.schemas.common` says how the two kinds of model guard that.
"""
