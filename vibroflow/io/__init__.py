"""File formats and file handling shared by the solvers: atomic writes (atomic), folder locks
(folder_lock), ParaView output (vtk) and calibration.toml (calibration_file).  The LIGGGHTS round
trip needs the DEM, which sits above io, so it is a package of its own: vibroflow.liggghts."""
