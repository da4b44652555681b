"""Result files: HDF5 (netCDF-4 compatible) writing and reading."""
