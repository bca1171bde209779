#pragma once
// A task's particle snapshots described for ParaView's and VisIt's Xdmf readers: an
// XML file beside the task's HDF5 file (same name, .xmf) with one grid per snapshot in
// a temporal collection, positions as the geometry, velocity and spin as vectors
// (joined from the vx/vy/vz and wx/wy/wz datasets), radius and fixed as scalars. The
// data stay in the HDF5 file's H5Part layout; this file only points into it, by the
// HDF5 file's name, so the two move together.
#include "hdf5_writer.hpp"

#include <string>
#include <vector>

namespace demcal::jobs {

// "runs/3-1a2b3c4d.h5" -> "runs/3-1a2b3c4d.xmf".
std::string xdmf_path_for(const std::string& h5_path);

// The XML text; h5_name is the HDF5 file's name relative to the .xmf file.
std::string snapshot_xdmf(const std::string& h5_name, const std::vector<Snapshot>& snapshots);

// Written to a part of this process's own and renamed into place; throws
// OutputWriteError naming the path and the reason when it cannot be written (the
// worker turns that into a warning: the .xmf is a viewing aid).
void write_snapshot_xdmf(const std::string& path, const std::string& h5_name, const std::vector<Snapshot>& snapshots);

}  // namespace demcal::jobs
