/// @file MemoryBudget.h
/// @brief Memory budgets: byte sizes as users write them, as messages show them, and the default.
#pragma once

#include <cstdint>
#include <string>

namespace vdbclay {

/// Scene::memoryBudget: no budget at all.
constexpr uint64_t kNoMemoryBudget = UINT64_MAX;
/// Parses a size such as "8G", "512M", "1.5GiB", "64k", "1000000" (bytes; K, M, G, T are powers of
/// 1024, with or without "i"/"B"), or "none"/"unlimited" (kNoMemoryBudget).
/// @throw Error naming @a text if it is not such a size or is 0.
uint64_t parseByteSize(const std::string& text);
/// "1.5 GiB", "512 MiB", "900 B": a size for messages.
std::string formatBytes(uint64_t bytes);

/// The budget a scene gets when Scene::memoryBudget is 0: three quarters of the memory this process
/// may use (physical memory, or the cgroup's memory.max where that is lower).
uint64_t defaultMemoryBudget();

} // namespace vdbclay
