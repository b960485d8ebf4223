// ivol verify FILE...: every checksum and every structural rule; exit 0 only
// for sound files. --json reports each file for machines with the SHA-256 of
// the whole file (fixity); --manifest writes those digests as a BagIt
// manifest; --against re-checks a conversion against its source.
#include <sys/stat.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <iostream>
#include <optional>

#include "commands.hpp"
#include "ivol/check.hpp"
#include "ivol/error.hpp"
#include "option_parsing.hpp"
#include "output_rules.hpp"
#include "salvage_report.hpp"
#include "sha256.hpp"
#include "staged_file.hpp"
#include "verify_against.hpp"

namespace ivol::cli {
namespace {

struct FileResult {
  std::string path;
  std::string status;       // ok, damaged, not-ivol, unsupported, missing, unreadable, mismatch
  std::string error_class;  // the spec's name of the first problem's class; empty when ok
  std::string message;      // why, when not checked at all
  std::optional<CheckReport> report;
  std::optional<FileDigest> digest;
  std::optional<AgainstReport> against;
};

FileResult examine(const std::string& path, bool want_digest) {
  FileResult r;
  r.path = path;
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) {
    const bool missing = errno == ENOENT || errno == ENOTDIR;
    r.status = missing ? "missing" : "unreadable";
    r.error_class = error_class_name(ErrorClass::Io);
    r.message = std::strerror(errno);
    return r;
  }
  if (!S_ISREG(st.st_mode)) {
    r.status = "unreadable";
    r.error_class = error_class_name(ErrorClass::Io);
    r.message = S_ISDIR(st.st_mode) ? "a directory, not a file" : "not a regular file";
    return r;
  }
  r.report = check_file(path);
  if (r.report->ok()) {
    r.status = "ok";
  } else {
    const ErrorClass first = r.report->problems.front().error_class;
    r.error_class = error_class_name(first);
    r.status = first == ErrorClass::NotIvol                                                         ? "not-ivol"
               : first == ErrorClass::Io                                                            ? "unreadable"
               : first == ErrorClass::UnsupportedVersion || first == ErrorClass::UnsupportedFeature ? "unsupported"
                                                                                                    : "damaged";
  }
  if (want_digest) {
    try {
      r.digest = digest_file(path);
    } catch (const Error& e) {
      r.status = "unreadable";
      r.error_class = error_class_name(e.error_class());
      r.message = e.what();
    }
  }
  return r;
}

nlohmann::json to_json(const FileResult& r) {
  nlohmann::json j = {{"path", r.path}, {"status", r.status}};
  j["error_class"] = r.error_class.empty() ? nlohmann::json(nullptr) : nlohmann::json(r.error_class);
  if (!r.message.empty()) j["message"] = r.message;
  if (r.digest) {
    j["bytes"] = r.digest->bytes;
    j["sha256"] = r.digest->sha256;
  }
  if (r.report) {
    nlohmann::json problems = nlohmann::json::array();
    for (const CheckProblem& p : r.report->problems)
      problems.push_back({{"error_class", error_class_name(p.error_class)}, {"message", p.message}});
    j["problems"] = problems;
    j["blocks_checked"] = r.report->blocks_checked;
    j["blocks_damaged"] = r.report->blocks_damaged;
    j["tree_checked"] = r.report->tree_checked;
  }
  if (r.against) j["against"] = r.against->to_json();
  return j;
}

// An octree's inner averages, a bricked grid's stored levels of detail
// (spec §8A.5): what check_file verified beyond the checksums.
std::string what_was_verified(const CheckReport& report) {
  if (!report.info || report.info->layout.kind == StructureKind::Octree) return "structure and averages verified";
  if (report.info->layout.kind == StructureKind::Bricked) return "structure and stored levels verified";
  return "structure verified";
}

void print_text(const FileResult& r, bool quiet) {
  if (r.status == "ok") {
    if (!quiet)
      std::cout << r.path << ": OK (" << r.report->blocks_checked << " blocks, " << what_was_verified(*r.report)
                << (r.digest ? ", sha256 " + r.digest->sha256 : std::string()) << ")\n";
  } else if (r.status == "missing" || (!r.report && r.status == "unreadable")) {
    std::cout << r.path << ": " << (r.status == "missing" ? "MISSING" : "UNREADABLE") << " (" << r.message << ")\n";
  } else if (r.status == "not-ivol") {
    std::cout << r.path << ": NOT AN IVOL FILE\n  " << r.error_class << ": " << r.report->problems.front().message
              << "\n";
  } else if (r.status == "mismatch") {
    std::cout << r.path << ": sound, but does NOT MATCH " << r.against->source << "\n";
  } else {
    std::cout << r.path << ": " << (r.status == "unsupported" ? "UNSUPPORTED" : "DAMAGED") << " ("
              << r.report->problems.size() << " problem" << (r.report->problems.size() == 1 ? "" : "s");
    if (r.report->blocks_checked)
      std::cout << ", " << r.report->blocks_damaged << " of " << r.report->blocks_checked << " blocks damaged";
    std::cout << ")\n";
    for (const CheckProblem& p : r.report->problems)
      std::cout << "  " << error_class_name(p.error_class) << ": " << p.message << "\n";
    if (r.status == "damaged" && !r.report->info) print_salvage_prospect(std::cout, "  ", r.path);  // no usable index
  }
  if (r.against) {
    const AgainstReport& a = *r.against;
    for (const std::string& p : a.source_problems) std::cout << "  source: " << p << "\n";
    if (!a.values_skipped.empty()) std::cout << "  values not compared: " << a.values_skipped << "\n";
    if (a.ok() && !quiet) {
      std::cout << "  against " << a.source << ": ";
      if (a.values_compared)
        std::cout << a.voxels << " voxels "
                  << (a.tolerance > 0 ? "within the recorded largest error " + std::to_string(a.tolerance) : "equal")
                  << ", ";
      std::cout << "source digests match\n";
    }
    if (a.differing) {
      std::cout << "  values: " << a.differing << " of " << a.voxels << " voxels differ"
                << (a.tolerance > 0 ? " by more than the recorded largest error" : "") << "; first:\n";
      for (const std::string& d : a.first_differences) std::cout << "    " << d << "\n";
    }
  }
}

// BagIt (RFC 8493 §2.1.3) manifest lines, "<sha256>  <path>", which
// `sha256sum -c` reads too. Written only when every file is sound.
void write_manifest(const std::string& path, const std::vector<FileResult>& results) {
  convert::StagedFile staged(path);
  {
    std::ofstream out(staged.temp_path(), std::ios::binary | std::ios::trunc);
    for (const FileResult& r : results) out << r.digest->sha256 << "  " << r.path << "\n";
    out.flush();
    if (!out) throw Error(ErrorClass::Io, path + ": cannot write the manifest");
  }
  staged.commit();
}

}  // namespace

Runner add_verify_command(CLI::App& app, const GlobalOptions& global) {
  auto* cmd = app.add_subcommand("verify", "Check every checksum and structural rule of .ivol files");
  struct Settings {
    std::vector<std::string> files;
    bool json = false;
    std::string manifest, against;
    bool force = false;
  };
  auto s = std::make_shared<Settings>();
  cmd->add_option("FILE", s->files, "The .ivol files")->required();
  cmd->add_flag("--json", s->json,
                "One JSON array: per file its status (ok, damaged, not-ivol, unsupported, missing, unreadable, "
                "mismatch), error class, problems, size and sha256");
  cmd->add_option("--manifest", s->manifest,
                  "Also write a BagIt manifest (<sha256>  <path> lines, sha256sum -c reads it) when every file is "
                  "sound");
  cmd->add_option("--against", s->against,
                  "SOURCE: re-check one converted file against its source: recorded digests and every value");
  cmd->add_flag("-f,--force", s->force, "Replace the manifest if it exists");
  return [s, &global]() {
    if (!s->against.empty() && s->files.size() != 1)
      throw UsageError("--against", "compares one .ivol file with its source; give one FILE");
    if (!s->manifest.empty()) {
      for (const std::string& f : s->files)
        if (f.find_first_of("\r\n") != std::string::npos)
          throw UsageError("--manifest", "a file name holds a line break; a manifest line cannot name it");
      check_output(s->manifest, "--manifest", s->files, s->force);
    }
    const bool digests = s->json || !s->manifest.empty();
    std::vector<FileResult> results;
    bool all_ok = true;
    for (const std::string& file : s->files) {
      FileResult r = examine(file, digests);
      if (r.status == "ok" && !s->against.empty()) {
        r.against = verify_against(s->against, file);
        if (!r.against->ok()) r.status = "mismatch";
      }
      all_ok = all_ok && r.status == "ok";
      if (!s->json) print_text(r, global.quiet);
      results.push_back(std::move(r));
    }
    if (s->json) {
      nlohmann::json list = nlohmann::json::array();
      for (const FileResult& r : results) list.push_back(to_json(r));
      // A problem message may quote the bytes of damaged metadata: replace
      // what is not UTF-8 rather than fail to report it.
      std::cout << list.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) << "\n";
    }
    if (!s->manifest.empty()) {
      if (!all_ok) {
        std::cerr << "ivol verify: " << s->manifest << " not written: not every file is sound\n";
      } else {
        write_manifest(s->manifest, results);
        if (!global.quiet && !s->json)
          std::cout << s->manifest << ": " << results.size() << " sha256 line" << (results.size() == 1 ? "" : "s")
                    << "\n";
      }
    }
    return all_ok ? kExitOk : kExitFailure;
  };
}

}  // namespace ivol::cli
