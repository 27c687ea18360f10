"""`fogmon batch`: many recordings analysed on Dask (inputs, exact chunking, the tasks,
the output tables, the fleet report)."""
