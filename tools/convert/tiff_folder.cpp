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
};

// A name's stem as alternating text and digit runs: text[0] digits[0]
// text[1] ... digits[n-1] text[n].
struct Tokens {
  std::vector<std::string> text;
  std::vector<std::string> digits;
};

Tokens tokenize(const std::string& name) {
  const std::string stem = std::filesystem::path(name).stem().string();
  Tokens t;
  t.text.emplace_back();
  for (std::size_t i = 0; i < stem.size();) {
    if (!std::isdigit(static_cast<unsigned char>(stem[i]))) {
      t.text.back() += stem[i++];
      continue;
    }
    std::size_t end = i;
    while (end < stem.size() && std::isdigit(static_cast<unsigned char>(stem[end]))) ++end;
    t.digits.push_back(stem.substr(i, end - i));
    t.text.emplace_back();
    i = end;
  }
  return t;
}

std::string without_zeros(const std::string& digits) {
  const std::size_t nonzero = digits.find_first_not_of('0');
  return nonzero == std::string::npos ? "0" : digits.substr(nonzero);
}

Numbered split_at(const std::string& name, const Tokens& t, std::size_t position) {
  Numbered n;
  n.name = name;
  for (std::size_t j = 0; j < t.text.size(); ++j) {
    std::string& part = j <= position ? n.prefix : n.suffix;
    part += t.text[j];
    if (j < t.digits.size() && j != position) part += t.digits[j];
  }
  n.digits = t.digits[position];
  n.number = without_zeros(n.digits).size() <= 18 ? std::stoull(n.digits) : 0;  // longer ones are refused
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

  // The slice number is the digit run that changes from file to file (the
  // last one when several do, or none: then the files repeat a number);
  // the text around the digit runs must be the same in every name.
  std::sort(names.begin(), names.end());
  std::vector<Tokens> tokens;
  std::vector<std::string> unnumbered;
  for (const std::string& name : names) {
    tokens.push_back(tokenize(name));
    if (tokens.back().digits.empty()) unnumbered.push_back(name);
  }
  if (!unnumbered.empty())
    throw Error(ErrorClass::Malformed, path(unnumbered[0]) + ": no slice number in the name (" + list(unnumbered) +
                                           " among " + std::to_string(names.size()) +
                                           " files), so the order of the slices is unknown; move "
                                           "what is not a slice out of the folder");
  const Tokens& reference = tokens[0];
  std::size_t position = reference.digits.size() - 1;
  for (std::size_t j = reference.digits.size(); j-- > 0;) {
    bool varies = false;
    for (const Tokens& t : tokens)
      varies = varies || (t.text == reference.text && without_zeros(t.digits[j]) != without_zeros(reference.digits[j]));
    if (varies) {
      position = j;
      break;
    }
  }
  const Numbered pattern = split_at(names[0], reference, position);
  for (std::size_t i = 0; i < names.size(); ++i) {
    if (tokens[i].text != reference.text)
      throw Error(ErrorClass::Malformed, path(names[i]) + " does not follow the numbering of " + names[0] + " (" +
                                             pattern.prefix + "<number>" + pattern.suffix +
                                             "); move what is not a slice out of the folder");
    if (without_zeros(tokens[i].digits[position]).size() > 18)
      throw Error(ErrorClass::Malformed,
                  path(names[i]) + ": slice number " + tokens[i].digits[position] + " is too long to be one");
  }
  std::vector<Numbered> slices;
  for (std::size_t i = 0; i < names.size(); ++i) slices.push_back(split_at(names[i], tokens[i], position));
  std::sort(slices.begin(), slices.end(), [](const Numbered& a, const Numbered& b) {
    return a.number != b.number ? a.number < b.number : a.name < b.name;
  });
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

Error several_pages_among_files(const std::string& file, const std::string& unit) {
  return Error(ErrorClass::Malformed, file + ": holds more than one page, but among several TIFF files each must be one " +
                                          unit + " (one number, one " + unit + "): its other pages would move every " +
                                          unit + " after it; convert a multi-page file on its own");
}

}  // namespace ivol::convert
