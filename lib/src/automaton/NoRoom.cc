// The no-room flood (see NoRoom.h).
#include "automaton/NoRoom.h"

#include <openvdb/openvdb.h>
#include <openvdb/tree/ValueAccessor.h>

#include <memory>
#include <vector>

namespace vdbclay {
namespace automaton_internal {

bool overloadHasNoRoom(const Tree543<int32_t>& mass, const Tree543<openvdb::ValueMask>* obstacles, int64_t tc,
                       int64_t overload, int64_t totalMass, bool is3D)
{
    using openvdb::Coord;
    using ObsAcc = openvdb::tree::ValueAccessor<const openvdb::MaskTree, false>;
    if (overload == 0) return false;
    const uint64_t limit = uint64_t((totalMass + tc - 1) / tc);
    std::unique_ptr<ObsAcc> oacc;
    if (obstacles) oacc = std::make_unique<ObsAcc>(*obstacles);
    auto obstacleAt = [&](const Coord& c) { return oacc && oacc->isValueOn(c); };
    openvdb::MaskTree seen(false);
    openvdb::tree::ValueAccessor<openvdb::MaskTree> sacc(seen);
    openvdb::tree::ValueAccessor<const openvdb::Int32Tree, false> macc(mass);
    std::vector<Coord> stack;
    for (auto it = mass.cbeginValueOn(); it; ++it) {
        if (int64_t(*it) <= tc || obstacleAt(it.getCoord())) continue;
        stack.push_back(it.getCoord());
        sacc.setValueOn(it.getCoord());
    }
    static const Coord kFace[6] = {Coord(1, 0, 0),  Coord(-1, 0, 0), Coord(0, 1, 0),
                                   Coord(0, -1, 0), Coord(0, 0, 1),  Coord(0, 0, -1)};
    const int faces = is3D ? 6 : 4;
    uint64_t cellsSeen = 0;
    int64_t massSeen = 0, room = 0;
    while (!stack.empty()) {
        const Coord c = stack.back();
        stack.pop_back();
        if (++cellsSeen > limit) return false;
        const int64_t m = macc.getValue(c);
        massSeen += m;
        if (m < tc && (room += tc - m) >= overload) return false;
        for (int f = 0; f < faces; ++f) {
            const Coord q = c + kFace[f];
            if (sacc.isValueOn(q) || obstacleAt(q)) continue;
            sacc.setValueOn(q);
            stack.push_back(q);
        }
    }
    return massSeen > tc * int64_t(cellsSeen);
}

} // namespace automaton_internal
} // namespace vdbclay
