#pragma once
// JSON from untrusted files (transforms.json, scene.json). nlohmann::json's
// copy, dump and comparison recurse once per nesting level, so a value nested
// a million deep overflows the stack: the parse refuses anything nested deeper
// than `max_depth` before such a value exists, with an InputError naming the file.
#include <filesystem>
#include <nlohmann/json.hpp>

namespace lfrecon {

constexpr int kMaxJsonDepth = 64;  // transforms.json needs 5 (root, frames, frame, matrix, row)

// Reads and parses `path`; throws InputError naming it (cannot open, not JSON, nested too deep).
nlohmann::json ReadJsonFile(const std::filesystem::path& path, int max_depth = kMaxJsonDepth);

}  // namespace lfrecon
