// Volumes in ITK's native image files (itk_image_header.hpp): read slab by
// slab with their spacing and origin, written as one file with them.
//
// Read: uint8, int16, uint16 and float32 samples as they are; int8 widened
// to int16 (exact). Other types are refused, naming the type: ivol holds
// 8- and 16-bit integers, binary16 and float32.
// Written: .mha (MetaImage, samples after the header, uncompressed: ITK's
// MetaImage needs the compressed size in the header before the samples) or
// .nrrd (NRRD, gzip-compressed as it is written); uint8, int16, uint16 or
// float32 samples, identity direction. MetaImage has no unit field (ITK's
// tools take millimetres), so spacing and origin are written in mm; NRRD
// states its "space units".
#pragma once

#include <memory>
#include <string>

#include "slab_io.hpp"

namespace ivol::convert {

std::unique_ptr<SlabReader> open_itk_image_slabs(const std::string& path);
// `path` ends in .mha or .nrrd.
std::unique_ptr<SlabWriter> create_itk_image_slabs(const std::string& path, const DenseVolume& shape);

}  // namespace ivol::convert
