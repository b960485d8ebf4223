#include "salvage_report.hpp"

#include "ivol/error.hpp"

namespace ivol::cli {

void print_salvage(std::ostream& out, const std::string& indent, const SalvageInfo& s, const VolumeLayout& layout) {
  out << indent << "salvaged from its blocks: " << s.blocks_used << " of " << s.blocks_found
      << " blocks found are usable, " << s.bytes_lost << " bytes after the header are in no block\n";
  out << indent << "metadata: "
      << (s.metadata == "complete" ? std::string("complete")
          : s.metadata == "early"  ? std::string("early metadata only (keys written later are missing)")
                                   : std::string("missing (defaults: voxel size 1, origin 0)"))
      << "\n";
  out << indent << "values: " << s.values_found << " found";
  if (s.values_total) out << " of " << s.values_total;
  out << "; ";
  if (s.finest_complete_lod < 0)
    out << "no level of detail is complete\n";
  else
    out << "complete down to level of detail " << s.finest_complete_lod
        << (s.finest_complete_lod == 0 ? " (full resolution)" : "") << "\n";
  for (std::size_t n = 0; n < s.gaps.size() && n < 5; ++n)
    out << indent << "  lost bytes " << s.gaps[n].first << " .. " << s.gaps[n].second << "\n";
  if (s.gaps.size() > 5) out << indent << "  ... " << s.gaps.size() - 5 << " more runs of lost bytes\n";
  for (std::size_t n = 0; n < s.notes.size() && n < 5; ++n) out << indent << "  " << s.notes[n] << "\n";
  if (s.notes.size() > 5) out << indent << "  ... " << s.notes.size() - 5 << " more blocks not used\n";
  if (layout.kind != StructureKind::Octree && s.finest_complete_lod < 0)
    out << indent << "missing cells of this grid read as the stored code 0 (a grid has no coarser level)\n";
}

void print_salvage_prospect(std::ostream& out, const std::string& indent, const std::string& file) {
  try {
    ReaderOptions options;
    options.salvage = true;
    Reader reader(file, options);
    if (!reader.info().salvage) return;  // opens fine with salvage: a damaged metadata block, reported already
    print_salvage(out, indent, *reader.info().salvage, reader.layout());
    out << indent << "(ivol extract --salvage reads what survived)\n";
  } catch (const Error& e) {
    const std::string what = e.what();
    const auto at = what.find("nothing can be salvaged: ");
    out << indent << "nothing can be salvaged" << (at == std::string::npos ? ": " + what : ": " + what.substr(at + 25))
        << "\n";
  } catch (const std::exception& e) {
    out << indent << "nothing can be salvaged: " << e.what() << "\n";
  }
}

}  // namespace ivol::cli
