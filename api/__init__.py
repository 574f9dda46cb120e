"""FastAPI app: MES REST API, operator panel, live streams, auth."""
