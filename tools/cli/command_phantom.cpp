// ivol phantom NAME -o OUT: simulates a circular cone-beam scan of an analytic
// phantom (recon/phantom.hpp) and writes its projections as DXchange HDF5 or
// raw float32 line integrals, the scan's RTK geometry file next to them, and
// optionally the phantom voxelized as an .ivol file (the ground truth a
// reconstruction is compared with). Prints the `ivol recon` command that
// reconstructs the scan.
//
// Every output is written under a temporary name and renamed into place only
// when all of them are complete, so a failure leaves nothing behind.
#include <algorithm>
#include <charconv>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <optional>
#include <sstream>
#include <thread>

#include "commands.hpp"
#include "fixity.hpp"
#include "ivol/error.hpp"
#include "ivol/recon/geometry.hpp"
#include "ivol/recon/phantom.hpp"
#include "ivol/recon/projections.hpp"
#include "ivol/recon/rtk_geometry_xml.hpp"
#include "ivol_io.hpp"
#include "option_parsing.hpp"
#include "output_rules.hpp"
#include "projection_io.hpp"
#include "report.hpp"
#include "signal_cleanup.hpp"
#include "staged_file.hpp"

namespace ivol::cli {
namespace {

struct PhantomSettings {
  std::string name, output, geometry_out, truth, encoding = "float32";
  std::string detector = "384", pitch, offset;
  std::size_t views = 360;
  double arc = 360.0, first_angle = 0.0, sid = 600.0, sdd = 1200.0, radius = 100.0, photons = 0.0;
  std::uint64_t seed = 1;
  int supersampling = 1;
  std::uint32_t truth_size = 0;
  bool force = false;
};

enum class ProjectionFormat { Dxchange, Raw };

// Everything the run needs, checked: a usage error is found before any work.
struct Plan {
  recon::Phantom phantom;
  recon::ScanGeometry geometry;
  ProjectionFormat format = ProjectionFormat::Dxchange;
  std::string geometry_path;
  std::vector<double> angles_deg;
  // The suggested reconstruction grid: size (x, y, z) of `voxel` mm.
  std::array<std::uint32_t, 3> recon_size{0, 0, 0};
  double recon_voxel = 0.0;
  std::optional<recon::VolumeGrid> truth;
};

// Shortest text that reads back as the same double.
std::string number(double value) {
  char text[32];
  const auto end = std::to_chars(text, text + sizeof text, value).ptr;
  return std::string(text, end);
}

// Three significant digits, for people.
std::string rounded(double value) {
  std::ostringstream out;
  out << std::setprecision(3) << value;
  return out.str();
}

// Rounds up to four significant digits, so that a default pitch is short to type.
double round_up_4(double x) {
  const int e = static_cast<int>(std::floor(std::log10(x))) - 3;
  const double scale = std::pow(10.0, std::abs(e));
  return e < 0 ? std::ceil(x * scale) / scale : std::ceil(x / scale) * scale;
}

// Rounds to three significant digits.
double round_3(double x) {
  const int e = static_cast<int>(std::floor(std::log10(x))) - 2;
  const double scale = std::pow(10.0, std::abs(e));
  return e < 0 ? std::round(x * scale) / scale : std::round(x / scale) * scale;
}

bool has_extension(const std::string& path, std::initializer_list<const char*> extensions) {
  std::string ext = std::filesystem::path(path).extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  for (const char* e : extensions)
    if (ext == e) return true;
  return false;
}

[[noreturn]] void usage(const std::string& what) { throw UsageError("", what); }

Plan make_plan(const PhantomSettings& s) {
  Plan plan;
  const auto names = recon::phantom_names();
  if (std::find(names.begin(), names.end(), s.name) == names.end()) {
    std::string list;
    for (const std::string& n : names) list += (list.empty() ? "" : ", ") + n;
    usage("unknown phantom '" + s.name + "'; known phantoms: " + list);
  }
  if (has_extension(s.output, {".h5", ".hdf5"}))
    plan.format = ProjectionFormat::Dxchange;
  else if (has_extension(s.output, {".raw"}))
    plan.format = ProjectionFormat::Raw;
  else
    usage(s.output + ": cannot tell the format; name it .h5 or .hdf5 (DXchange) or .raw (float32)");
  if (!(s.radius > 0.0)) usage("--radius must be positive");
  if (!(s.sid > s.radius)) usage("--sid must exceed --radius (the source would be inside the field)");
  if (!(s.sdd > s.sid)) usage("--sdd must exceed --sid");
  if (!(s.arc > 0.0) || s.arc > 360.0) usage("--arc must be in (0, 360] degrees");
  if (!std::isfinite(s.first_angle)) usage("--first-angle must be finite");
  if (!(s.photons >= 0.0) || !std::isfinite(s.photons)) usage("--photons must be positive (0: no noise)");
  if (s.truth_size && s.truth.empty()) usage("--truth-size needs --truth");
  if (!s.truth.empty() && !has_extension(s.truth, {".ivol"})) usage("--truth: " + s.truth + " is not an .ivol file");
  if (!s.geometry_out.empty() && !has_extension(s.geometry_out, {".xml"}))
    usage("--geometry-out: " + s.geometry_out + " is not an .xml name");

  const auto cells = parse_numbers(s.detector, "--detector", 1, 2);
  for (double c : cells)
    if (c < 1.0 || c > 65536.0 || c != std::floor(c)) usage("--detector: '" + s.detector + "' is not C[,R] pixels");
  recon::Detector d;
  d.columns = static_cast<int>(cells[0]);
  d.rows = static_cast<int>(cells.back());
  if (s.pitch.empty()) {
    // The detector sees the tangents to the field's cylinder, with 10 % spare.
    const double half_width = 1.1 * s.sdd * s.radius / std::sqrt(s.sid * s.sid - s.radius * s.radius);
    d.pitch_u = d.pitch_v = round_up_4(2.0 * half_width / d.columns);
  } else {
    const auto pitch = parse_numbers(s.pitch, "--pitch", 1, 2);
    d.pitch_u = pitch[0];
    d.pitch_v = pitch.back();
    if (!(d.pitch_u > 0.0) || !(d.pitch_v > 0.0)) usage("--pitch must be positive");
  }
  double offset_u = 0.0, offset_v = 0.0;
  if (!s.offset.empty()) {
    const auto offset = parse_numbers(s.offset, "--offset", 2, 2);
    offset_u = offset[0];
    offset_v = offset[1];
  }
  const double radians = M_PI / 180.0;
  plan.geometry =
      recon::circular_scan(d, s.views, s.sid, s.sdd, s.arc * radians, s.first_angle * radians, offset_u, offset_v);
  plan.geometry.validate();
  for (std::size_t i = 0; i < s.views; ++i)
    plan.angles_deg.push_back(s.first_angle + static_cast<double>(i) * s.arc / static_cast<double>(s.views));
  plan.phantom = recon::named_phantom(s.name, s.radius);

  // The reconstruction grid: voxels of the detector pitch at the isocentre,
  // enough of them to cover the field across and what the detector sees along z.
  const double magnification = s.sdd / s.sid;
  plan.recon_voxel = round_3(std::min(d.pitch_u, d.pitch_v) / magnification);
  const auto across = static_cast<std::uint32_t>(std::ceil(2.0 * s.radius / plan.recon_voxel - 1e-9));
  const double height = d.rows * d.pitch_v / magnification;
  const auto along = static_cast<std::uint32_t>(std::max(1.0, std::floor(height / plan.recon_voxel)));
  plan.recon_size = {across, across, std::min(across, along)};

  plan.geometry_path =
      s.geometry_out.empty() ? std::filesystem::path(s.output).replace_extension(".xml").string() : s.geometry_out;
  if (!s.truth.empty()) {
    // By default the truth has the suggested reconstruction's grid, voxel for voxel.
    recon::VolumeGrid grid;
    if (s.truth_size)
      grid = recon::VolumeGrid::centred({s.truth_size, s.truth_size, s.truth_size}, 2.0 * s.radius / s.truth_size);
    else
      grid = recon::VolumeGrid::centred(plan.recon_size, plan.recon_voxel);
    plan.truth = grid;
  }
  const std::string outputs[] = {s.output, plan.geometry_path, s.truth};
  for (int a = 0; a < 3; ++a)
    for (int b = a + 1; b < 3; ++b)
      if (!outputs[a].empty() && !outputs[b].empty() &&
          std::filesystem::absolute(outputs[a]).lexically_normal() ==
              std::filesystem::absolute(outputs[b]).lexically_normal())
        usage(outputs[a] + ": named for two outputs");
  return plan;
}

std::uint64_t splitmix64(std::uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

// The scan, simulated a batch of views at a time as the writers read it view
// by view: memory holds one batch, never the whole scan. Noise of view v is
// drawn from its own generator seeded with (seed, v), so it does not depend on
// the batches.
class SimulatedScan : public recon::ProjectionSource {
 public:
  SimulatedScan(const Plan& plan, int supersampling, double photons, std::uint64_t seed, convert::Progress progress)
      : plan_(plan), supersampling_(supersampling), photons_(photons), seed_(seed), progress_(std::move(progress)) {
    const std::size_t image_bytes = image_size() * sizeof(float);
    batch_ = std::max<std::size_t>(std::max(1u, std::thread::hardware_concurrency()), (64u << 20) / image_bytes);
    batch_ = std::min(batch_, view_count());
  }
  int columns() const override { return plan_.geometry.detector.columns; }
  int rows() const override { return plan_.geometry.detector.rows; }
  std::size_t view_count() const override { return plan_.geometry.view_count(); }

  void read_rows(std::size_t view, int row_begin, int row_end, float* out) override {
    if (view >= view_count() || row_begin < 0 || row_end > rows() || row_begin > row_end)
      throw std::out_of_range("simulated scan: view " + std::to_string(view) + " rows " + std::to_string(row_begin) +
                              ".." + std::to_string(row_end) + " do not exist");
    if (!images_ || view < first_ || view >= first_ + images_->view_count()) simulate(view);
    const float* image = images_->view_data(view - first_) + std::size_t(row_begin) * columns();
    std::copy(image, image + std::size_t(row_end - row_begin) * columns(), out);
  }

 private:
  std::size_t image_size() const { return std::size_t(columns()) * std::size_t(rows()); }

  void simulate(std::size_t first) {
    recon::ScanGeometry part;
    part.detector = plan_.geometry.detector;
    const std::size_t end = std::min(view_count(), first + batch_);
    part.views.assign(plan_.geometry.views.begin() + static_cast<std::ptrdiff_t>(first),
                      plan_.geometry.views.begin() + static_cast<std::ptrdiff_t>(end));
    images_.reset();  // one batch in memory at a time
    images_.emplace(recon::project_scan(plan_.phantom, part, supersampling_));
    first_ = first;
    if (photons_ > 0.0)
      for (std::size_t v = first; v < end; ++v)
        recon::add_poisson_noise(images_->view_data(v - first), image_size(), photons_,
                                 splitmix64(seed_ ^ splitmix64(v)));
    if (progress_) progress_(end, view_count());
  }

  const Plan& plan_;
  int supersampling_;
  double photons_;
  std::uint64_t seed_;
  convert::Progress progress_;
  std::size_t batch_ = 1;
  std::size_t first_ = 0;
  std::optional<recon::InMemoryProjections> images_;
};

// The phantom voxelized a slab at a time, for import_to_ivol.
class VoxelizedPhantom : public convert::SlabReader {
 public:
  VoxelizedPhantom(const recon::Phantom& phantom, const recon::VolumeGrid& grid, int supersampling)
      : phantom_(phantom), grid_(grid), supersampling_(supersampling) {
    shape_.dims = {grid.size[0], grid.size[1], grid.size[2]};
    shape_.type = convert::SampleType::Float32;
    shape_.voxel_size = grid.voxel_size;
    shape_.origin = grid.origin;
    shape_.unit = "mm";
    shape_.has_geometry = true;
  }
  void read(std::uint32_t z0, std::uint32_t count, void* out) override {
    recon::voxelize(phantom_, grid_, z0, z0 + count, static_cast<float*>(out), supersampling_);
  }

 private:
  const recon::Phantom& phantom_;
  recon::VolumeGrid grid_;
  int supersampling_;
};

std::string pair_text(double a, double b) { return a == b ? number(a) : number(a) + "," + number(b); }

// The command line, for provenance.
std::string command_line(const PhantomSettings& s, const recon::Detector& d) {
  std::string c = "ivol phantom " + s.name + " -o " + shell_quote(s.output) + " --views " + std::to_string(s.views) +
                  " --arc " + number(s.arc) + " --first-angle " + number(s.first_angle) + " --detector " +
                  std::to_string(d.columns) + "," + std::to_string(d.rows) + " --pitch " +
                  pair_text(d.pitch_u, d.pitch_v) + " --sid " + number(s.sid) + " --sdd " + number(s.sdd) +
                  " --radius " + number(s.radius) + " --supersampling " + std::to_string(s.supersampling);
  if (!s.offset.empty()) c += " --offset " + s.offset;
  if (s.photons > 0.0) c += " --photons " + number(s.photons) + " --seed " + std::to_string(s.seed);
  if (!s.truth.empty())
    c += " --truth " + shell_quote(s.truth) + (s.truth_size ? " --truth-size " + std::to_string(s.truth_size) : "") +
         " --encoding " + s.encoding;
  return c;
}

}  // namespace

Runner add_phantom_command(CLI::App& app, const GlobalOptions& global) {
  std::string names;
  for (const std::string& n : recon::phantom_names()) names += (names.empty() ? "" : ", ") + n;
  auto* cmd = app.add_subcommand("phantom", "Simulate a circular cone-beam scan of an analytic phantom");
  cmd->footer("Phantoms: " + names +
              ".\nWrites OUT's RTK geometry file next to it (OUT with .xml) and prints the `ivol recon` command "
              "that reconstructs the scan.");
  auto s = std::make_shared<PhantomSettings>();
  cmd->add_option("NAME", s->name, "Phantom: " + names)->required();
  cmd->add_option("-o,--output", s->output, "Projections: .h5/.hdf5 (DXchange) or .raw (float32 line integrals)")
      ->required();
  cmd->add_flag("-f,--force", s->force, "Replace outputs that exist");
  cmd->add_option("--geometry-out", s->geometry_out, "RTK geometry file (default: OUT with .xml)");
  auto* scan = cmd->add_option_group("scan");
  scan->add_option("--views", s->views, "Number of projections")->check(CLI::Range(1, 1 << 20))->capture_default_str();
  scan->add_option("--arc", s->arc, "Degrees the views span (360: full circle, first view not repeated)")
      ->check(number_in(0, 360, true))
      ->capture_default_str();
  scan->add_option("--first-angle", s->first_angle, "Gantry angle of the first view, degrees")
      ->check(number_in(-1e6, 1e6))
      ->capture_default_str();
  scan->add_option("--detector", s->detector, "C[,R]: detector columns and rows")->capture_default_str();
  scan->add_option("--pitch", s->pitch,
                   "U[,V] mm per pixel (default: the detector sees the field's cylinder at SDD/SID, 10 % spare)");
  scan->add_option("--sid", s->sid, "Source to isocentre, mm")->check(number_in(0, 1e9, true))->capture_default_str();
  scan->add_option("--sdd", s->sdd, "Source to detector, mm")->check(number_in(0, 1e9, true))->capture_default_str();
  scan->add_option("--offset", s->offset, "U,V: detector offset, mm");
  scan->add_option("--radius", s->radius, "Radius of the field the phantom is sized to, mm")
      ->check(number_in(0, 1e9, true))
      ->capture_default_str();
  scan->add_option("--photons", s->photons, "Incident photons per pixel: Poisson noise (default: none)")
      ->check(number_in(0, 1e30));
  scan->add_option("--seed", s->seed, "Seed of the noise")->check(whole_number())->capture_default_str();
  scan->add_option("--supersampling", s->supersampling, "Rays per pixel side (and samples per truth voxel side)")
      ->check(CLI::Range(1, 16))
      ->capture_default_str();
  auto* truth = cmd->add_option_group("ground truth");
  truth->add_option("--truth", s->truth, "Also write the phantom voxelized as this .ivol file");
  truth
      ->add_option(
          "--truth-size", s->truth_size,
          "N: a centred N³ grid across the field (default: the suggested reconstruction's grid, voxel for voxel)")
      ->check(CLI::Range(1, 4096));
  truth->add_option("--encoding", s->encoding, "float32 (lossless) or binary16")
      ->check(CLI::IsMember({"float32", "binary16"}))
      ->capture_default_str();

  return [s, &global]() {
    const auto start = std::chrono::steady_clock::now();
    Plan plan;
    try {
      plan = make_plan(*s);
    } catch (const std::exception& e) {  // Error(InvalidArgument) and the library's std::invalid_argument
      std::cerr << "ivol phantom: " << e.what() << "\n";
      return kExitUsage;
    }
    std::vector<OutputFile> outputs{{s->output, "-o", false}, {plan.geometry_path, "--geometry-out", false}};
    if (!s->truth.empty()) outputs.push_back({s->truth, "--truth", false});
    check_outputs(outputs, {}, s->force);
    for (const OutputFile& output : outputs) remove_temporaries_on_signal(output.path);

    // Temporary files first: a missing or read-only folder fails before any work.
    convert::StagedFile projections_file(s->output);
    convert::StagedFile geometry_file(plan.geometry_path);
    std::optional<convert::StagedFile> truth_file;
    if (plan.truth) truth_file.emplace(s->truth);

    const recon::Detector& d = plan.geometry.detector;
    SimulatedScan scan(plan, s->supersampling, s->photons, s->seed, progress_bar("ivol phantom", global.quiet));
    if (plan.format == ProjectionFormat::Dxchange)
      convert::write_dxchange(projections_file.temp_path(), scan, plan.angles_deg);
    else
      convert::write_raw_projections(projections_file.temp_path(), scan);
    recon::write_rtk_geometry_xml(geometry_file.temp_path(), plan.geometry, -0.5 * (d.columns - 1) * d.pitch_u,
                                  -0.5 * (d.rows - 1) * d.pitch_v);
    std::optional<convert::ImportReport> truth_report;
    if (plan.truth) {
      const recon::VolumeGrid& grid = *plan.truth;
      VoxelizedPhantom source(plan.phantom, grid, s->supersampling);
      convert::ImportOptions options;
      options.encoding = parse_encoding(s->encoding);
      options.metadata.quantity = "linear_attenuation";
      options.metadata.value_unit = "1/mm";
      options.metadata.provenance = default_provenance();
      options.metadata.provenance["command"] = global.command_line;
      // The command with every default spelled out: the same scan again, whatever later versions default to.
      options.metadata.provenance["command_resolved"] = command_line(*s, d);
      options.metadata.provenance["sources"] = {{{"phantom", s->name},
                                                 {"format", "analytic"},
                                                 {"fov_radius_mm", s->radius},
                                                 {"supersampling", s->supersampling}}};
      options.metadata.provenance["phantom_grid"] = {
          {"size", grid.size}, {"voxel_size_mm", grid.voxel_size}, {"origin_mm", grid.origin}, {"centred", true}};
      options.progress = progress_bar("ivol phantom: truth", global.quiet);
      truth_report = convert::import_to_ivol(source, truth_file->temp_path(), options);
    }
    if (truth_file) truth_file->commit();
    geometry_file.commit();
    projections_file.commit();

    if (!global.quiet) {
      const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      const bool raw = plan.format == ProjectionFormat::Raw;
      std::cout << s->name << " phantom (field radius " << number(s->radius) << " mm): " << s->views << " views over "
                << number(s->arc) << "° from " << number(s->first_angle) << "°, detector " << d.columns << " x "
                << d.rows << " pixels of " << number(d.pitch_u) << " x " << number(d.pitch_v) << " mm, SID "
                << number(s->sid) << " mm, SDD " << number(s->sdd) << " mm"
                << (s->photons > 0 ? ", " + number(s->photons) + " photons per pixel" : std::string(", no noise"))
                << "\n";
      std::cout << "  " << s->output << "  " << (raw ? "raw float32" : "DXchange") << " line integrals, " << s->views
                << " x " << d.rows << " x " << d.columns << "\n"
                << "  " << plan.geometry_path << "  RTK geometry\n";
      if (plan.truth) {
        const recon::VolumeGrid& g = *plan.truth;
        std::cout << "  " << s->truth << "  truth, " << g.size[0] << " x " << g.size[1] << " x " << g.size[2]
                  << " voxels of " << number(g.voxel_size[0]) << " mm, " << encoding_name(truth_report->encoding)
                  << (truth_report->lossless ? " (lossless)"
                                             : " (largest error " + rounded(truth_report->max_abs_error) + ")")
                  << ", " << human_bytes(truth_report->file_bytes) << "\n";
      }
      const auto& n = plan.recon_size;
      const std::string size = n[0] == n[2]
                                   ? std::to_string(n[0])
                                   : std::to_string(n[0]) + "," + std::to_string(n[1]) + "," + std::to_string(n[2]);
      std::cout << "in " << number(std::round(seconds * 100) / 100) << " s; reconstruct with:\n  ivol recon "
                << shell_quote(s->output) << " --geometry " << shell_quote(plan.geometry_path) << " --pitch "
                << pair_text(d.pitch_u, d.pitch_v)
                << (raw ? " --detector " + std::to_string(d.columns) + "," + std::to_string(d.rows) + " --views " +
                              std::to_string(s->views)
                        : std::string())
                << " -o volume.ivol --size " << size << " --voxel " << number(plan.recon_voxel) << "\n";
    }
    return kExitOk;
  };
}

}  // namespace ivol::cli
