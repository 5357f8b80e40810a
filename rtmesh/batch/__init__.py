"""rtmesh batch: inputs, the ledger of finished assets, local and Dask worker pools, one job."""
