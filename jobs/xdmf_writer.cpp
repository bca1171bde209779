#include "xdmf_writer.hpp"

#include "part_file.hpp"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>
#include <stdexcept>

namespace demcal::jobs {
namespace {

std::string xml_escaped(const std::string& text) {
  std::string out;
  for (const char c : text) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      default: out += c;
    }
  }
  return out;
}

std::string number(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

void data_item(std::ostream& out, const std::string& indent, std::size_t n, const std::string& h5_name,
               std::size_t step, const char* dataset) {
  out << indent << "<DataItem Dimensions=\"" << n << "\" NumberType=\"Float\" Precision=\"8\" Format=\"HDF\">"
      << xml_escaped(h5_name) << ":/" << snapshot_group(step) << "/" << dataset << "</DataItem>\n";
}

void scalar(std::ostream& out, std::size_t n, const std::string& h5_name, std::size_t step, const char* name) {
  out << "        <Attribute Name=\"" << name << "\" AttributeType=\"Scalar\" Center=\"Node\">\n";
  data_item(out, "          ", n, h5_name, step, name);
  out << "        </Attribute>\n";
}

// Xdmf's JOIN makes an n x 3 array of three n-long ones without copying the data.
void vector(std::ostream& out, std::size_t n, const std::string& h5_name, std::size_t step, const char* name,
            const char* const (&parts)[3]) {
  out << "        <Attribute Name=\"" << name << "\" AttributeType=\"Vector\" Center=\"Node\">\n"
      << "          <DataItem ItemType=\"Function\" Function=\"JOIN($0, $1, $2)\" Dimensions=\"" << n << " 3\">\n";
  for (const char* p : parts) data_item(out, "            ", n, h5_name, step, p);
  out << "          </DataItem>\n        </Attribute>\n";
}

}  // namespace

std::string xdmf_path_for(const std::string& h5_path) {
  const std::string ext = ".h5";
  const bool has_ext = h5_path.size() > ext.size() && h5_path.compare(h5_path.size() - ext.size(), ext.size(), ext) == 0;
  return (has_ext ? h5_path.substr(0, h5_path.size() - ext.size()) : h5_path) + ".xmf";
}

std::string snapshot_xdmf(const std::string& h5_name, const std::vector<Snapshot>& snapshots) {
  std::ostringstream out;
  out << "<?xml version=\"1.0\" ?>\n<!DOCTYPE Xdmf SYSTEM \"Xdmf.dtd\" []>\n<Xdmf Version=\"2.0\">\n  <Domain>\n"
      << "    <Grid Name=\"snapshots\" GridType=\"Collection\" CollectionType=\"Temporal\">\n";
  for (std::size_t step = 0; step < snapshots.size(); ++step) {
    const Snapshot& s = snapshots[step];
    const std::size_t n = s.x.size();
    if (n == 0) continue;  // an empty grid stops ParaView's reader for that time
    out << "      <Grid Name=\"" << xml_escaped(s.label.empty() ? "snapshot" : s.label) << "\" GridType=\"Uniform\">\n"
        << "        <Time Value=\"" << number(s.time) << "\"/>\n"
        << "        <Topology TopologyType=\"Polyvertex\" NumberOfElements=\"" << n << "\" NodesPerElement=\"1\"/>\n"
        << "        <Geometry GeometryType=\"X_Y_Z\">\n";
    for (const char* axis : {"x", "y", "z"}) data_item(out, "          ", n, h5_name, step, axis);
    out << "        </Geometry>\n";
    scalar(out, n, h5_name, step, "radius");
    vector(out, n, h5_name, step, "velocity", {"vx", "vy", "vz"});
    vector(out, n, h5_name, step, "spin", {"wx", "wy", "wz"});
    scalar(out, n, h5_name, step, "fixed");
    out << "      </Grid>\n";
  }
  out << "    </Grid>\n  </Domain>\n</Xdmf>\n";
  return out.str();
}

void write_snapshot_xdmf(const std::string& path, const std::string& h5_name, const std::vector<Snapshot>& snapshots) {
  PartFile file = PartFile::private_to_this_process(path);  // two runs may describe one task at once
  {
    std::ofstream f(file.part(), std::ios::trunc);
    f << snapshot_xdmf(h5_name, snapshots);
    f.close();
    if (!f) throw OutputWriteError("cannot write the Xdmf file " + file.part() + ": " + std::strerror(errno));
  }
  file.commit("Xdmf file");
}

}  // namespace demcal::jobs
