// What the fuzz targets count as a bug: any exception other than a vdbclay::Error with a message.
#pragma once

#include "vdbclay/Types.h"

#include <cstdio>
#include <cstdlib>
#include <exception>

namespace vdbclay::fuzz {

/// Runs @a body; returns normally if it succeeds or refuses the input with a vdbclay::Error that
/// says something. Aborts (libFuzzer then keeps the input as a crash) on an Error with an empty
/// message or on any other exception escaping the library.
template <typename Body> void expectOnlyErrors(Body&& body)
{
    try {
        body();
    } catch (const Error& e) {
        if (e.what()[0] == '\0') {
            std::fprintf(stderr, "fuzz: vdbclay::Error with an empty message\n");
            std::abort();
        }
    } catch (const std::exception& e) {
        std::fprintf(stderr, "fuzz: a non-vdbclay exception escaped: %s\n", e.what());
        std::abort();
    } catch (...) {
        std::fprintf(stderr, "fuzz: a non-std exception escaped\n");
        std::abort();
    }
}

} // namespace vdbclay::fuzz
