// What a dense volume says about itself beyond its samples (geometry,
// quantity, value unit, provenance), as the converters carry it between
// formats, and the conversion summary's account of where each value came
// from (README "Geometry through the formats").
//
// An unknown voxel size is never invented silently: a volume whose source
// gives none (and no --voxel-size) has has_geometry false, the summary warns,
// and the output's provenance carries "voxel_size_known": false (an .ivol
// file then records voxel_size 1, 1, 1 in unit "pixel"). Readers of ivol's
// own outputs (.ivol, TIFF tag 65369, HDF5 and OpenVDB provenance) take that
// key back as an unknown voxel size.
#pragma once

#include <array>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "dense_volume.hpp"
#include "slab_io.hpp"

namespace ivol::convert {

// The keys of an .ivol metadata block that describe a dense volume:
// voxel_size, origin, unit (only with has_geometry), value {quantity, unit},
// provenance.
nlohmann::json metadata_json(const DenseVolume& shape);
// The reverse; throws Error(Malformed), naming `where` and the key, for a key
// of the wrong type or a voxel size that is not positive.
void apply_metadata_json(const nlohmann::json& json, const std::string& where, DenseVolume& shape);

// Whether a provenance JSON text says "voxel_size_known": false.
bool voxel_size_marked_unknown(const std::string& provenance);

// The provenance an output carries: this conversion's (software, created,
// command, sources [{path, format, sample_type}]: the direct input, as
// ivol verify --against expects), with the source's own provenance, when it
// has one, kept whole under "derived_from" (which may hold its own
// derived_from, further back). "voxel_size_known": false is set to match
// shape.has_geometry.
nlohmann::json provenance_after_conversion(const DenseVolume& shape, const std::string& command,
                                           const std::string& input, const std::string& input_format);

// The summary's lines: voxel size, origin and unit with where they came from
// ("(from OME-TIFF PhysicalSize)", "(from --voxel-size)", "(default: none in
// the file)"), quantity and value unit when known, then the reader's notes.
std::vector<std::string> geometry_summary(const DenseVolume& shape);

// "mm", "um", "nm", "cm", "m" for the spellings of those units (micron,
// µm, \u00B5m, metre, ...); "" for pixel / no unit; other text as it is.
std::string normalise_length_unit(const std::string& unit);
// Factor from `unit` to `to` (both normalised), or 0 when unknown.
double length_unit_factor(const std::string& unit, const std::string& to);

// The same slabs under another shape (geometry and metadata overridden).
std::unique_ptr<SlabReader> reshaped_slabs(std::unique_ptr<SlabReader> inner, const DenseVolume& shape);

}  // namespace ivol::convert
