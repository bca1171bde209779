#include "hdf5_writer.hpp"

#include "part_file.hpp"
#include "physics_version.hpp"

#include "engine/particles.hpp"

#include <H5Cpp.h>

#include <algorithm>
#include <filesystem>
#include <memory>
#include <sstream>
#include <stdexcept>

namespace demcal::jobs {
namespace {

H5::DataSet write_column(H5::Group& g, const std::string& name, const std::vector<double>& data) {
  const hsize_t n = data.size();
  H5::DataSpace space(1, &n);
  H5::DSetCreatPropList props;
  if (n > 0) {
    const hsize_t chunk = std::min<hsize_t>(n, 4096);
    props.setChunk(1, &chunk);
    props.setShuffle();
    props.setDeflate(4);
  }
  // No chunk cache: the chunks go to the file in write(), so that a full disk shows
  // there, as an exception, and not in the DataSet's destructor, which prints
  // "H5Dclose failed" on stderr and cannot be caught.
  H5::DSetAccPropList access;
  access.setChunkCache(0, 0, 1.0);
  H5::DataSet ds = g.createDataSet(name, H5::PredType::NATIVE_DOUBLE, space, props, access);
  if (n > 0) ds.write(data.data(), H5::PredType::NATIVE_DOUBLE);
  return ds;
}

void string_attr(H5::H5Object& obj, const std::string& name, const std::string& value) {
  H5::StrType type(H5::PredType::C_S1, std::max<std::size_t>(1, value.size()));
  H5::Attribute a = obj.createAttribute(name, type, H5::DataSpace(H5S_SCALAR));
  a.write(type, value);
}

void double_attr(H5::H5Object& obj, const std::string& name, double value) {
  H5::Attribute a = obj.createAttribute(name, H5::PredType::NATIVE_DOUBLE, H5::DataSpace(H5S_SCALAR));
  a.write(H5::PredType::NATIVE_DOUBLE, &value);
}

void int_attr(H5::H5Object& obj, const std::string& name, std::int64_t value) {
  H5::Attribute a = obj.createAttribute(name, H5::PredType::NATIVE_INT64, H5::DataSpace(H5S_SCALAR));
  a.write(H5::PredType::NATIVE_INT64, &value);
}

std::string read_string_attr(const H5::H5Object& obj, const std::string& name) {
  H5::Attribute a = obj.openAttribute(name);
  std::string out;
  a.read(a.getStrType(), out);
  return out;
}

void write_series(H5::Group& root, const engine::Series& s) {
  H5::Group g = root.createGroup(s.name);
  std::string cols;
  for (const auto& c : s.columns) cols += (cols.empty() ? "" : ",") + c;
  string_attr(g, "columns", cols);
  for (std::size_t c = 0; c < s.columns.size(); ++c) {
    std::vector<double> col;
    col.reserve(s.rows.size());
    for (const auto& row : s.rows) col.push_back(c < row.size() ? row[c] : 0.0);
    H5::DataSet ds = write_column(g, s.columns[c], col);
    if (c < s.units.size()) string_attr(ds, "units", s.units[c]);
  }
}

void write_snapshot(H5::H5File& f, std::size_t step, const Snapshot& s) {
  H5::Group g = f.createGroup(snapshot_group(step));
  double_attr(g, "TimeValue", s.time);
  string_attr(g, "TimeValue_units", "s");  // H5Part's TimeValue is a bare number
  string_attr(g, "label", s.label.empty() ? "snapshot" : s.label);
  struct Column {
    const char* name;
    const std::vector<double>* data;
    const char* units;
  };
  const Column cols[] = {{"x", &s.x, "m"},         {"y", &s.y, "m"},   {"z", &s.z, "m"},  {"radius", &s.radius, "m"},
                         {"vx", &s.vx, "m/s"}, {"vy", &s.vy, "m/s"}, {"vz", &s.vz, "m/s"},
                         {"wx", &s.wx, "rad/s"}, {"wy", &s.wy, "rad/s"}, {"wz", &s.wz, "rad/s"},
                         {"fixed", &s.fixed, "1"}};
  for (const Column& c : cols) {
    H5::DataSet ds = write_column(g, c.name, *c.data);
    string_attr(ds, "units", c.units);
  }
}

// The error for a failed write, judged while its part file is still on disk.
OutputWriteError write_failed(const std::string& path, const H5::Exception& e) {
  std::filesystem::path dir = std::filesystem::path(path).parent_path();
  if (dir.empty()) dir = ".";
  const bool full = !folder_takes_a_file(dir);
  return OutputWriteError("cannot write the HDF5 file " + path + ": " + e.getDetailMsg() +
                              (full ? " (the folder takes no further file: " + why_folder_takes_no_file(dir) + ")"
                                    : " (is the disk full, or the folder not writable?)"),
                          full);
}

}  // namespace

std::string snapshot_group(std::size_t step) { return "Step#" + std::to_string(step); }

void SnapshotObserver::on_snapshot(const std::string& label, double time, const engine::Particles& p) {
  if (!keep_) return;
  Snapshot s;
  s.label = label;
  s.time = time;
  for (std::size_t i = 0; i < p.size(); ++i) {
    s.x.push_back(p.x[i].x());
    s.y.push_back(p.x[i].y());
    s.z.push_back(p.x[i].z());
    s.radius.push_back(p.r[i]);
    s.vx.push_back(p.v[i].x());
    s.vy.push_back(p.v[i].y());
    s.vz.push_back(p.v[i].z());
    s.wx.push_back(p.w[i].x());
    s.wy.push_back(p.w[i].y());
    s.wz.push_back(p.w[i].z());
    s.fixed.push_back(p.fixed[i] ? 1.0 : 0.0);
  }
  snapshots.push_back(std::move(s));
}

void write_task_hdf5(const std::string& path, const TaskFileInfo& info, const nlohmann::json& params,
                     const std::vector<engine::Series>& series, const std::vector<Snapshot>& snapshots) {
  H5::Exception::dontPrint();
  // Written beside the final name and renamed when whole: a run stopped mid-write
  // (or a full disk) leaves no file at the recorded path that looks valid.
  // Two runs may write the same task's file at once (one task in two databases whose
  // output folders are one): each writes its own part.
  PartFile file = PartFile::private_to_this_process(path);
  // The file is closed exactly once: when HDF5 fails to close it (a full disk shows
  // there, as cached chunks are written out), the C++ destructor's second H5Fclose
  // of the same id crashed in H5F__close. So the cache is flushed first, and the
  // file closed once whatever fails, never by the destructor after a failure (the
  // object is let go: a worker process exits after its task; the part file is
  // removed all the same).
  std::unique_ptr<H5::H5File> f_owner;
  try {
    f_owner = std::make_unique<H5::H5File>(file.part(), H5F_ACC_TRUNC);
    H5::H5File& f = *f_owner;
    string_attr(f, "scene", info.scene);
    string_attr(f, "params", params.dump());
    string_attr(f, "task_key", info.task_key);
    string_attr(f, "status", info.status);
    if (!info.message.empty()) string_attr(f, "message", info.message);
    int_attr(f, "task_id", info.task_id);
    int_attr(f, "physics_version", static_cast<std::int64_t>(physics_version(info.scene)));
    H5::Group root = f.createGroup("series");
    for (const auto& s : series) write_series(root, s);
    for (std::size_t i = 0; i < snapshots.size(); ++i) write_snapshot(f, i, snapshots[i]);
    root.close();
    f.flush(H5F_SCOPE_GLOBAL);  // a full disk throws here, with the file still whole to close
  } catch (const H5::Exception& e) {
    if (f_owner) H5Fclose(f_owner.release()->getId());  // once, and without the destructor's line on stderr
    throw write_failed(path, e);
  }
  try {
    f_owner->close();
  } catch (const H5::Exception& e) {
    (void)f_owner.release();  // its destructor would close it a second time
    throw write_failed(path, e);
  }
  file.commit("HDF5 file");
}

namespace {

// Why a task's file cannot be read, in words: HDF5's own detail ("H5Fopen failed")
// does not tell a truncated file from one that is not HDF5 at all.
std::runtime_error unreadable(const std::string& path, const H5::Exception& e) {
  std::error_code ec;
  const auto size = std::filesystem::file_size(path, ec);
  std::string why;
  if (ec) {
    why = ec.message();
  } else if (size == 0) {
    why = "an empty file";
  } else {
    const std::string bytes = " (" + std::to_string(size) + " bytes)";
    why = H5Fis_hdf5(path.c_str()) > 0 ? "an HDF5 file that cannot be read" + bytes +
                                             ": cut short, damaged, or held by a writer (HDF5: " + e.getDetailMsg() + ")"
                                       : "not an HDF5 file" + bytes + ": damaged or overwritten";
  }
  return std::runtime_error("cannot read " + path + ": " + why);
}

}  // namespace

std::string read_task_key(const std::string& path) {
  H5::Exception::dontPrint();
  try {
    H5::H5File f(path, H5F_ACC_RDONLY);
    return f.attrExists("task_key") ? read_string_attr(f, "task_key") : std::string();
  } catch (const H5::Exception& e) {
    throw unreadable(path, e);
  }
}

engine::Series read_series(const std::string& path, const std::string& name) {
  H5::Exception::dontPrint();
  try {
    H5::H5File f(path, H5F_ACC_RDONLY);
    if (!f.nameExists("series/" + name)) throw std::runtime_error(path + " has no series \"" + name + "\"");
    H5::Group g = f.openGroup("series/" + name);
    engine::Series s;
    s.name = name;
    std::stringstream cols(read_string_attr(g, "columns"));
    for (std::string c; std::getline(cols, c, ',');) s.columns.push_back(c);
    std::vector<std::vector<double>> data;
    for (const auto& c : s.columns) {
      H5::DataSet ds = g.openDataSet(c);
      s.units.push_back(ds.attrExists("units") ? read_string_attr(ds, "units") : "");
      hsize_t n = 0;
      ds.getSpace().getSimpleExtentDims(&n);
      std::vector<double> col(n);
      if (n > 0) ds.read(col.data(), H5::PredType::NATIVE_DOUBLE);
      data.push_back(std::move(col));
    }
    const std::size_t rows = data.empty() ? 0 : data[0].size();
    for (std::size_t r = 0; r < rows; ++r) {
      std::vector<double> row;
      for (const auto& col : data) row.push_back(r < col.size() ? col[r] : 0.0);
      s.rows.push_back(std::move(row));
    }
    return s;
  } catch (const H5::Exception& e) {
    throw unreadable(path, e);
  }
}

std::vector<std::string> series_names(const std::string& path) {
  H5::Exception::dontPrint();
  std::vector<std::string> out;
  try {
    H5::H5File f(path, H5F_ACC_RDONLY);
    H5::Group g = f.openGroup("series");
    for (hsize_t i = 0; i < g.getNumObjs(); ++i) out.push_back(g.getObjnameByIdx(i));
  } catch (const H5::Exception& e) {
    throw unreadable(path, e);
  }
  return out;
}

}  // namespace demcal::jobs
