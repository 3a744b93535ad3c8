"""The wire format of the REST API: pydantic models, one module per resource (the OpenAPI
document is generated from them). Light: importing them loads neither numpy, gtsam nor OpenCV."""
