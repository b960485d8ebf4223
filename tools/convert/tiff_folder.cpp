#include "tiff_folder.hpp"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <system_error>

#include "ivol/error.hpp"

namespace ivol::convert {
namespace {

bool is_tiff_name(const std::string& name) {
  std::string ext = std::filesystem::path(name).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  return ext == ".tif" || ext == ".tiff";
}

// A name split around its slice number: prefix, digits, suffix (the
// extension excluded from the suffix, so that s1.tif and s1.tiff collide).
struct Numbered {
  std::string name;
  std::string prefix;
  std::string digits;
  std::string suffix;
  unsigned long long number = 0;
  bool has_number = false;
};

Numbered split_number(const std::string& name) {
  Numbered n;
  n.name = name;
  const std::string stem = std::filesystem::path(name).stem().string();
  std::size_t end = stem.size();
  while (end > 0 && !std::isdigit(static_cast<unsigned char>(stem[end - 1]))) --end;
  std::size_t begin = end;
  while (begin > 0 && std::isdigit(static_cast<unsigned char>(stem[begin - 1]))) --begin;
  if (begin == end || end - begin > 18) {  // no number, or one too long to be a slice index
    n.prefix = stem;
    return n;
  }
  n.prefix = stem.substr(0, begin);
  n.digits = stem.substr(begin, end - begin);
  n.suffix = stem.substr(end);
  n.number = std::stoull(n.digits);
  n.has_number = true;
  return n;
}

// The name slice `number` would have, spelled like `like` (same padding).
std::string name_for(const Numbered& like, unsigned long long number) {
  std::string digits = std::to_string(number);
  if (digits.size() < like.digits.size()) digits.insert(0, like.digits.size() - digits.size(), '0');
  return like.prefix + digits + like.suffix + std::filesystem::path(like.name).extension().string();
}

std::string list(const std::vector<std::string>& names, std::size_t most = 5) {
  std::string text;
  for (std::size_t i = 0; i < names.size() && i < most; ++i) text += (i ? ", " : "") + names[i];
  if (names.size() > most) text += " and " + std::to_string(names.size() - most) + " more";
  return text;
}

}  // namespace

TiffFolder scan_tiff_folder(const std::string& folder, const TiffFolderOptions& options) {
  const std::string dir = folder.size() > 1 && folder.back() == '/' ? folder.substr(0, folder.size() - 1) : folder;
  auto path = [&](const std::string& name) { return dir + "/" + name; };
  std::vector<std::string> names, hidden;
  std::error_code ec;
  for (std::filesystem::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (!name.empty() && name[0] == '.') {
      if (is_tiff_name(name) || name == ".DS_Store") hidden.push_back(name);
      continue;
    }
    std::error_code type_ec;
    if (it->is_regular_file(type_ec) && is_tiff_name(name)) names.push_back(name);
  }
  if (ec) throw Error(ErrorClass::Io, dir + ": cannot list the folder (" + ec.message() + ")");
  TiffFolder out;
  if (!hidden.empty()) {
    std::sort(hidden.begin(), hidden.end());
    out.notes.push_back("skipped hidden file" + std::string(hidden.size() > 1 ? "s " : " ") + list(hidden) + " in " +
                        dir + " (macOS AppleDouble or dotfiles, not slices)");
  }
  if (names.empty()) throw Error(ErrorClass::InvalidArgument, dir + ": the folder holds no .tif or .tiff files");
  if (names.size() == 1) {
    out.files.push_back(path(names[0]));
    return out;
  }

  std::vector<Numbered> slices;
  for (const std::string& name : names) slices.push_back(split_number(name));
  std::sort(slices.begin(), slices.end(), [](const Numbered& a, const Numbered& b) {
    return a.has_number != b.has_number ? a.has_number : a.number != b.number ? a.number < b.number : a.name < b.name;
  });
  std::vector<std::string> unnumbered;
  for (const Numbered& s : slices)
    if (!s.has_number) unnumbered.push_back(s.name);
  if (!unnumbered.empty())
    throw Error(ErrorClass::Malformed, path(unnumbered[0]) + ": no slice number in the name (" + list(unnumbered) +
                                           " among " + std::to_string(names.size()) +
                                           " files), so the order of the slices is unknown; move "
                                           "what is not a slice out of the folder");
  const Numbered& first = slices.front();
  for (const Numbered& s : slices)
    if (s.prefix != first.prefix || s.suffix != first.suffix)
      throw Error(ErrorClass::Malformed, path(s.name) + " does not follow the numbering of " + first.name + " (" +
                                             first.prefix + "<number>" + first.suffix +
                                             "); move what is not a slice out of the folder");
  unsigned long long step = ~0ull;
  for (std::size_t i = 1; i < slices.size(); ++i) {
    if (slices[i].number == slices[i - 1].number)
      throw Error(ErrorClass::Malformed, path(slices[i].name) + " and " + slices[i - 1].name +
                                             " have the same slice number " + std::to_string(slices[i].number) +
                                             "; keep one of them");
    step = std::min(step, slices[i].number - slices[i - 1].number);
  }
  std::vector<std::string> gaps, notes;
  for (std::size_t i = 1; i < slices.size(); ++i) {
    const unsigned long long before = slices[i - 1].number, after = slices[i].number;
    if (after - before == step) continue;
    const unsigned long long missing = (after - before) / step - ((after - before) % step == 0 ? 1 : 0);
    std::string what = name_for(slices[i - 1], before + step);
    if (missing > 1)
      what += " .. " + name_for(slices[i - 1], after - step) + " (" + std::to_string(missing) + " slices)";
    gaps.push_back(slices[i].name + " follows " + slices[i - 1].name + ": " + what + (missing > 1 ? " are" : " is") +
                   " missing");
    notes.push_back(dir + "/" + gaps.back() + ": converted without " + (missing > 1 ? "them" : "it") +
                    " (--allow-gaps)");
  }
  if (!gaps.empty() && !options.allow_gaps) {
    const std::size_t more = gaps.size() - 1;
    throw Error(ErrorClass::Malformed,
                dir + "/" + gaps[0] +
                    (more ? " (and " + std::to_string(more) + " more gap" + (more > 1 ? "s)" : ")") : std::string()) +
                    "; " + options.gap_hint);
  }
  out.notes.insert(out.notes.end(), notes.begin(), notes.end());
  for (const Numbered& s : slices) out.files.push_back(path(s.name));
  return out;
}

}  // namespace ivol::convert
