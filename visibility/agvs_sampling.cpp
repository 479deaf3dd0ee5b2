#include "visibility/agvs.h"
#include "visibility/agvs_internal.h"
#include "visibility/discovery_rays.h"

#include <tuple>

// Drawing and casting samples: the worker each thread runs, a batch, sampling from a box.

namespace vistream::visibility {

// --- Drawing and casting samples (read-only on the sampler; one per thread). ---

namespace {

class Worker {
 public:
  using Impl = GlobalSampler::Impl;
  Worker(const Impl& impl, const ViewcellGrid& grid, const GlobalPvs& pvs, const AgvsOptions& options)
      : s_(impl), grid_(grid), pvs_(pvs), options_(options) {}

  // See GlobalSampler::SampleFromBox.
  std::vector<BoxHit> FromBox(const Aabb& box, size_t rays, uint64_t seed) {
    Rng rng(seed);
    ChunkResult scratch;
    out_ = &scratch;
    std::vector<BoxHit> hits;
    const glm::dvec3 lo = box.min - s_.frame, ext = box.Extent();
    for (size_t i = 0; i < rays; ++i) {
      const glm::dvec3 p = lo + glm::dvec3(rng.Uniform() * ext.x, rng.Uniform() * ext.y, rng.Uniform() * ext.z);
      glm::dvec3 dir;
      if (i % 2 == 0 || s_.surface.empty()) {
        dir = UniformDirection(rng);
      } else {
        glm::dvec3 n;
        ObjectId o;
        const glm::dvec3 q = SurfacePoint(rng, &o, &n) - p;
        const double len = glm::length(q);
        if (!(len > 0.0)) continue;
        dir = q / len;
      }
      const Hit h = Cast(p, dir, 0.0);
      if (h.object == kNoObject || h.back) continue;
      const uint32_t triangle = s_.objects[h.object].TriangleOf(h.quad, h.second);
      hits.push_back({h.object, triangle, s_.frame + p, s_.frame + p + h.t * dir});
    }
    return hits;
  }

  void Run(const ChunkPlan& plan, uint64_t seed, ChunkResult* out) {
    Rng rng(seed);
    out_ = out;
    if (!plan.candidates.empty()) Gather(plan);
    if (plan.dist == Distribution::kObjectDirection || plan.dist == Distribution::kTwoPoint) {
      SurfaceChunk(plan.dist, rng);
      return;
    }
    for (uint32_t i = 0; i < kChunk; ++i) {
      switch (plan.dist) {
        case Distribution::kViewSpaceDirection: {
          Sample smp;
          smp.dist = plan.dist;
          smp.origin = ViewSpacePoint(rng, &smp.origin_cell);
          smp.dir = UniformDirection(rng);
          CastBoth(&smp, false);
          Emit(smp);
          break;
        }
        case Distribution::kRef: {
          Sample smp;
          smp.dist = plan.dist;
          smp.origin = ViewSpacePoint(rng, &smp.origin_cell);
          smp.dir = UniformDirection(rng);
          Hit h = Cast(smp.origin, smp.dir, 0.0);
          smp.valid = !h.back;
          smp.t_fwd = h.t;
          smp.fwd = h.object;
          smp.t_rev = 0.0;
          Emit(smp);
          break;
        }
        case Distribution::kObjectDirection:
        case Distribution::kTwoPoint:
          // Drawn for the whole chunk at once (SurfaceChunk).
          break;
        case Distribution::kTwoPointMutation: {
          const Candidate& c = candidates_[i];
          const double len = glm::length(c.to - c.from);  // positive: see add_candidate in Emit
          const glm::dvec3 u = (c.to - c.from) / len;
          glm::dvec3 b1, b2;
          Basis(u, &b1, &b2);
          const auto [g1, g2] = Gaussians(rng);
          const auto [g3, g4] = Gaussians(rng);
          const glm::dvec3 from = c.from + c.r_from * (g1 * b1 + g2 * b2);
          const glm::dvec3 to = c.to + c.r_to * (g3 * b1 + g4 * b2);
          EmitSegment(from, to, plan.dist);
          break;
        }
        case Distribution::kSilhouetteMutation: {
          // The next candidate's object's surface (where it lies was gathered with the candidates).
          if (i + 1 < kChunk) FanSurface::Prefetch(fans_[i + 1]);
          const Candidate& c = candidates_[i];
          const glm::dvec3 to = Silhouette(c.from, c.to, c.r_to, c.object, rng);
          const Sample smp = EmitSegment(c.from, to, plan.dist, true);
          if (!smp.valid || smp.fwd == kNoObject) break;
          // A depth discontinuity behind the silhouette: search the silhouette again from the
          // far hit point back towards the view space (the reverse sampling of GVS).
          const glm::dvec3 hit = smp.origin + smp.t_fwd * smp.dir;
          if (glm::length(hit - to) > options_.depth_discontinuity_k * c.r_to) {
            const glm::dvec3 back = Silhouette(hit, to, c.r_to, c.object, rng);
            EmitSegment(hit, back, plan.dist);
          }
          break;
        }
      }
    }
  }

 private:
  // The chunk's candidates, and where their objects' surfaces are, copied in one loop before
  // the samples: they lie scattered in memory, and a loop of independent loads waits for many
  // cache misses at once where the samples would wait for each in turn.
  void Gather(const ChunkPlan& plan) {
    candidates_.resize(plan.candidates.size());
    for (size_t i = 0; i < plan.candidates.size(); ++i) candidates_[i] = s_.buffer.At(plan.candidates[i]);
    fans_.resize(plan.candidates.size());
    for (size_t i = 0; i < plan.candidates.size(); ++i) {
      const ObjectId o = candidates_[i].object;
      fans_[i] = o < s_.objects.size() ? s_.objects[o].fan.hot() : FanSurface::Hot{};
    }
  }

  // A chunk of object-direction or two-point samples, each of which starts from a surface
  // point. The random numbers do not depend on what the samples hit, so the whole chunk's are
  // drawn first, in the order one sample after the other draws them (the same samples as
  // drawing and casting each in turn); the alias table's entries they pick are prefetched
  // then, and read once all are on their way. The table is over 100 MB for a city: entry
  // after entry, each would be a cache miss waited for alone.
  void SurfaceChunk(Distribution dist, Rng& rng) {
    if (s_.surface.empty()) return;
    ahead_.resize(kChunk);
    xs_.resize(kChunk);
    picks_.resize(kChunk);
    const double columns = static_cast<double>(s_.surface.size());
    for (uint32_t i = 0; i < kChunk; ++i) {
      Ahead& a = ahead_[i];
      if (dist == Distribution::kTwoPoint) a.view = ViewSpacePoint(rng, &a.cell);
      xs_[i] = rng.Uniform() * columns;
      a.u = rng.Uniform();
      a.v = rng.Uniform();
      if (dist == Distribution::kObjectDirection) {
        std::tie(a.cos_phi, a.sin_phi) = UniformCircle(rng);
        a.cos_t = std::sqrt(rng.Uniform());
      }
    }
    s_.surface.PickMany(xs_, picks_);
    for (uint32_t i = 0; i < kChunk; ++i) {
      const Ahead& a = ahead_[i];
      glm::dvec3 n;
      ObjectId o;
      const glm::dvec3 p = PointOn(s_.surface[picks_[i]], a.u, a.v, &o, &n);
      if (dist == Distribution::kTwoPoint) {
        EmitSegment(a.view, p, dist);
        continue;
      }
      glm::dvec3 b1, b2;
      Basis(n, &b1, &b2);
      const double sin_t = std::sqrt(std::max(0.0, 1.0 - a.cos_t * a.cos_t));
      Sample smp;
      smp.dist = dist;
      smp.origin = p;
      smp.dir = sin_t * a.cos_phi * b1 + sin_t * a.sin_phi * b2 + a.cos_t * n;
      smp.t_rev = 0.0;
      smp.rev = o;
      // The segment runs from the surface point forwards only: if the view space lies behind
      // it or off the line, or the ray ends before it, the sample adds nothing (CastBoth).
      double near = 0.0, far = 0.0;
      const bool meets = ViewSpaceSpan(s_.view_space, p, smp.dir, &near, &far) && far >= 0.0;
      const Hit h = meets ? Cast(p, smp.dir, kSurfaceOffset, near) : Hit{};
      smp.misses = !meets || h.short_of_reach;
      // A point on a face that another solid covers (a party wall, a tier's floor on the roof
      // below: coincident faces) lies on that solid's boundary, and the ray leaves it into the
      // solid: a sample from inside an object, discarded like one that meets a back face.
      smp.valid = !h.back && !Covered(picks_[i], p);
      smp.t_fwd = h.t;
      smp.fwd = h.object;
      Emit(smp);
    }
  }
  // Whether frame-relative point `p` of surface entry `entry` lies on a face of opposite
  // orientation (CoincidentFaces): the inside of the solid that face bounds.
  bool Covered(uint32_t entry, const glm::dvec3& p) const {
    const ObjectId o = s_.surface[entry].object;
    if (!options_.backface_rule || s_.coincident_quads[o] == nullptr) return false;
    return s_.OnCoincidentFace(o, s_.surface.TriangleOf(entry), p);
  }

  // A sample's random numbers but the surface point's column, drawn ahead (SurfaceChunk).
  struct Ahead {
    glm::dvec3 view{0.0};  // two-point: the view space point
    CellId cell = 0;
    double u = 0.0, v = 0.0;  // the surface point's barycentrics
    double cos_phi = 0.0, sin_phi = 0.0, cos_t = 0.0;  // object-direction: the direction's
  };

  struct Hit {
    double t = kInf;
    ObjectId object = kNoObject;
    uint32_t quad = 0;    // Embree's primitive
    bool second = false;  // in the quad's second triangle
    bool back = false;
    bool short_of_reach = false;  // met something before the reach asked for: t, object unknown
  };

  glm::dvec3 ViewSpacePoint(Rng& rng, CellId* cell) {
    const CellId c = static_cast<CellId>(rng.Below(grid_.CellCount()));
    const Aabb box = grid_.CellBox(c);
    const glm::dvec3 lo = box.min - s_.frame, ext = box.Extent();
    *cell = c;
    return lo + glm::dvec3(rng.Uniform() * ext.x, rng.Uniform() * ext.y, rng.Uniform() * ext.z);
  }

  // Precondition: the alias table is not empty.
  glm::dvec3 SurfacePoint(Rng& rng, ObjectId* id, glm::dvec3* normal) {
    // One uniform picks the column and, with its fraction, whether to keep it.
    const uint32_t entry = s_.surface.Pick(rng.Uniform() * static_cast<double>(s_.surface.size()));
    const double u = rng.Uniform(), v = rng.Uniform();
    return PointOn(s_.surface[entry], u, v, id, normal);
  }

  // The point of barycentrics (u, v), folded into the triangle, of the entry's triangle.
  static glm::dvec3 PointOn(const SurfaceTable::Entry& e, double u, double v, ObjectId* id, glm::dvec3* normal) {
    *id = e.object;
    const glm::dvec3 a(e.tri.a), e1(e.tri.e1), e2(e.tri.e2);
    if (u + v > 1.0) {
      u = 1.0 - u;
      v = 1.0 - v;
    }
    const glm::dvec3 n = glm::cross(e1, e2);
    const double len = glm::length(n);
    *normal = len > 0.0 ? n / len : glm::dvec3(0, 0, 1);
    return a + u * e1 + v * e2;
  }

  // The first hit along origin + t dir for t >= tnear. With `reach` past tnear, a ray that
  // meets anything before `reach` returns short_of_reach, what it met unknown: an occlusion
  // query, which stops at any hit, tells that for less than the search for the nearest one,
  // which then starts at `reach`. Either way it counts as one ray.
  Hit Cast(const glm::dvec3& origin, const glm::dvec3& dir, double tnear, double reach = 0.0) {
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    RTCRayHit rh;
    rh.ray.org_x = static_cast<float>(origin.x);
    rh.ray.org_y = static_cast<float>(origin.y);
    rh.ray.org_z = static_cast<float>(origin.z);
    rh.ray.dir_x = static_cast<float>(dir.x);
    rh.ray.dir_y = static_cast<float>(dir.y);
    rh.ray.dir_z = static_cast<float>(dir.z);
    rh.ray.tnear = static_cast<float>(tnear);
    if (!std::isfinite(rh.ray.org_x + rh.ray.org_y + rh.ray.org_z + rh.ray.dir_x + rh.ray.dir_y + rh.ray.dir_z)) {
      Hit bad;
      bad.back = true;  // discarded, as a ray Embree cannot take
      return bad;
    }
    // The ground z = 0 is solid: a ray ends where it reaches it (no object seen), and a ray
    // from beneath it is not a sample.
    const double height = origin.z + s_.frame.z;
    if (!(height >= 0.0)) {
      Hit bad;
      bad.back = true;  // discarded, like a ray that starts inside a solid
      return bad;
    }
    // A millimetre past the ground, so that a building's floor, which lies on it, is still met
    // (from inside: a back face, and the sample is discarded).
    const double ground_t = dir.z < 0.0 ? height / -dir.z : kInf;
    rh.ray.tfar = ground_t < kInf ? static_cast<float>(ground_t + 1e-3) : std::numeric_limits<float>::infinity();
    rh.ray.mask = ~0u;
    rh.ray.flags = 0;
    rh.ray.time = 0.0f;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    ++out_->embree_rays;
    // The largest float below `reach`: what the query meets lies before it, and the search
    // then meets nothing before it, so neither tells `reach` apart from where it rounds to.
    float below = 0.0f;
    if (reach > tnear) {
      below = std::nextafter(static_cast<float>(reach), 0.0f);
      if (static_cast<double>(below) >= reach) below = std::nextafter(below, 0.0f);
    }
    if (below > rh.ray.tnear) {
      RTCRay query = rh.ray;
      query.tfar = std::min(query.tfar, below);
      rtcOccluded1(s_.rtc, &ctx, &query);
      if (query.tfar < 0.0f) {
        Hit blocked;
        blocked.short_of_reach = true;
        return blocked;
      }
      rh.ray.tnear = below;
    }
    rtcIntersect1(s_.rtc, &ctx, &rh);
    Hit h;
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) {
      h.t = ground_t;
      return h;
    }
    h.t = rh.ray.tfar;
    h.object = rh.hit.geomID;
    h.quad = rh.hit.primID;
    h.second = rh.hit.u + rh.hit.v > 1.0f;
    // Embree's geometry normal is cross(v1 - v0, v2 - v0), as the meshes' outward normals are
    // (counter-clockwise seen from outside); reading it here saves a cache miss per ray.
    h.back = options_.backface_rule && rh.hit.Ng_x * dir.x + rh.hit.Ng_y * dir.y + rh.hit.Ng_z * dir.z > 0.0;
    if (options_.backface_rule && !h.back && s_.coincident_quads[h.object] != nullptr) {
      const uint32_t word = s_.coincident_quads[h.object][h.quad];
      if (Impl::Object::HitsCoincident(word, h.second)) {
        const uint32_t triangle = Impl::Object::TriangleOfWord(word, h.second);
        h.back = s_.OnCoincidentFace(h.object, triangle, origin + static_cast<double>(h.t) * dir);
      }
    }
    return h;
  }

  // Casts the sample's rays both ways, but leaves uncast what cannot count: the free segment
  // adds its two ends to the cells it crosses, so a line that misses the view space adds
  // nothing, and neither does one whose ray towards the view space ends before reaching it,
  // whatever the other ray would meet (Sample::misses). That ray is cast first, asking first
  // whether anything lies before the view space (Cast's reach). Decided as Emit's walk
  // decides which cells a segment crosses, so every sample that adds something finds the
  // same hits as when both rays were always cast. `whole`: both rays in full, for a segment
  // whose far hit is read even if it adds nothing (the silhouette mutation).
  void CastBoth(Sample* smp, bool whole) {
    double a = -kInf, b = kInf;
    if (!ViewSpaceSpan(s_.view_space, smp->origin, smp->dir, &a, &b) && !whole) {
      smp->misses = true;
      return;
    }
    const FirstRay plan = FirstRayOf(a, b, whole);
    const bool reverse_first = plan.reverse;
    const Hit first = Cast(smp->origin, reverse_first ? -smp->dir : smp->dir, 0.0, plan.reach);
    if (first.short_of_reach) {
      smp->misses = true;
      return;
    }
    (reverse_first ? smp->t_rev : smp->t_fwd) = first.t;
    (reverse_first ? smp->rev : smp->fwd) = first.object;
    if (first.back) {
      // Starts inside a solid: discarded whatever the other way holds, so that ray is not cast.
      smp->valid = false;
      return;
    }
    const Hit second = Cast(smp->origin, reverse_first ? smp->dir : -smp->dir, 0.0);
    (reverse_first ? smp->t_fwd : smp->t_rev) = second.t;
    (reverse_first ? smp->fwd : smp->rev) = second.object;
    smp->valid = !second.back;
  }

  // The sample on the line from `a` to `b`, cast both ways from their midpoint (CastBoth).
  Sample EmitSegment(const glm::dvec3& a, const glm::dvec3& b, Distribution dist, bool whole = false) {
    Sample smp;
    smp.dist = dist;
    const glm::dvec3 d = b - a;
    const double len = glm::length(d);
    smp.origin = 0.5 * (a + b);
    smp.dir = len > 0.0 && std::isfinite(len) ? d / len : glm::dvec3(0, 0, 1);
    CastBoth(&smp, whole);
    Emit(smp);
    return smp;
  }

  // The point near `to`, just off `object`'s silhouette seen from `from`, along a random
  // direction in the plane through `to` normal to the segment (SilhouetteLambda: exact, where
  // the paper searches with discovery rays); `to` + radius along it when there is none.
  glm::dvec3 Silhouette(const glm::dvec3& from, const glm::dvec3& to, double radius, ObjectId object, Rng& rng) {
    const glm::dvec3 seg = to - from;
    const double len = glm::length(seg);
    if (!(len > 0.0) || object >= s_.objects.size()) return to;
    glm::dvec3 b1, b2;
    Basis(seg / len, &b1, &b2);
    const auto [cos_phi, sin_phi] = UniformCircle(rng);
    const glm::dvec3 d = cos_phi * b1 + sin_phi * b2;
    const glm::dvec3 far = to + radius * d;
    if (!s_.objects[object].alive || !(radius > 0.0)) return far;
    ++out_->silhouette_searches;
    const DiscoveryFan fan{from, to, d, radius};
    const Impl::Object& o = s_.objects[object];
    const std::optional<double> lambda = o.alone != nullptr ? DiscoveryLambda(fan, o.alone, &out_->embree_rays)
                                                            : SilhouetteLambda(fan, o.fan, &fan_);
    if (!lambda) return far;
    // Just past the silhouette, on the side of the rays that miss, by as much as the paper's
    // quaternary search of depth 3 leaves (a 64th of the radius), at random.
    return to + (*lambda + (1.0 - rng.Uniform()) / 64.0) * radius * d;
  }

  // Walks the viewcells the sample's free segment pierces and records what is new in them,
  // how often its cells and objects were sampled, and (AGVS) its mutation candidates.
  // Whether frame-relative point `p` lies below the terrain's surface (inside the ground).
  bool BelowGround(const glm::dvec3& p) const {
    if (s_.terrain == nullptr) return false;
    const glm::dvec3 q = p + s_.frame;
    return q.z < s_.terrain->HeightAt(glm::dvec2(q));
  }

  void Emit(const Sample& smp) {
    ChunkResult& out = *out_;
    ++out.samples;
    if (smp.misses) return;
    if (!smp.valid || BelowGround(smp.origin)) {
      ++out.discarded;
      return;
    }
    if (smp.dist == Distribution::kRef) {
      if (counts_ != nullptr) {
        ++counts_->cells[smp.origin_cell];
        if (smp.fwd != kNoObject) ++counts_->objects[smp.fwd];
      }
      // A ref ray is a camera ray too: a uniform point and direction in a uniform cell.
      ++out.estimator_rays;
      if (smp.fwd != kNoObject && !pvs_.Contains(smp.origin_cell, smp.fwd)) {
        ++out.estimator_hits;
        out.entries.push_back({smp.origin_cell, smp.fwd, WitnessOf(smp.origin_cell, smp, 0.0, smp.t_fwd)});
        ++out.contribution;
      }
      return;
    }
    if (smp.dist == Distribution::kViewSpaceDirection) {
      // The estimator's camera rays: each direction from a uniform point is one.
      out.estimator_rays += 2;
      out.estimator_hits += (smp.fwd != kNoObject && !pvs_.Contains(smp.origin_cell, smp.fwd)) +
                            (smp.rev != kNoObject && !pvs_.Contains(smp.origin_cell, smp.rev));
    }
    // The cells first, with the set lines their tests read prefetched; then the tests, in the
    // same order (a segment crosses tens of cells, each test a likely cache miss).
    walk_.clear();
    VisitCells(grid_, s_.view_space, smp.origin, smp.dir, -smp.t_rev, smp.t_fwd, [&](CellId cell, double t) {
      walk_.emplace_back(cell, t);
      if (smp.fwd != kNoObject) pvs_.Prefetch(cell, smp.fwd);
      if (smp.rev != kNoObject) pvs_.Prefetch(cell, smp.rev);
    });
    if (walk_.empty()) return;
    // The first and last cell's points along the segment.
    const double t_first = walk_.front().second, t_last = walk_.back().second;
    if (counts_ != nullptr) {
      // Per-object sampling densities from the view space, for the object-space filter.
      if (smp.rev != kNoObject) ++counts_->objects[smp.rev];
      if (smp.fwd != kNoObject) ++counts_->objects[smp.fwd];
    }
    uint32_t c_fwd = 0, c_rev = 0;
    for (const auto& [cell, t] : walk_) {
      // Every valid segment counts towards its cells' sampling density (the object-space filter).
      if (counts_ != nullptr) ++counts_->cells[cell];
      if (smp.fwd != kNoObject && !pvs_.Contains(cell, smp.fwd)) {
        out.entries.push_back({cell, smp.fwd, WitnessOf(cell, smp, t, smp.t_fwd)});
        ++c_fwd;
      }
      if (smp.rev != kNoObject && !pvs_.Contains(cell, smp.rev)) {
        out.entries.push_back({cell, smp.rev, WitnessOf(cell, smp, t, -smp.t_rev)});
        ++c_rev;
      }
    }
    out.contribution += c_fwd + c_rev;
    if (options_.strategy != SamplingStrategy::kAgvs) return;
    // Contributing ends become mutation candidates: from the other end (a hit, or where the
    // segment leaves the view space) to the hit point.
    auto add_candidate = [&](bool fwd_end) {
      Candidate cand;
      cand.object = fwd_end ? smp.fwd : smp.rev;
      cand.to = smp.origin + (fwd_end ? smp.t_fwd : -smp.t_rev) * smp.dir;
      cand.r_to = s_.objects[cand.object].radius;
      const ObjectId other = fwd_end ? smp.rev : smp.fwd;
      if (other != kNoObject) {
        cand.from = smp.origin + (fwd_end ? -smp.t_rev : smp.t_fwd) * smp.dir;
        cand.r_from = s_.objects[other].radius;
      } else {
        cand.from = smp.origin + (fwd_end ? t_first : t_last) * smp.dir;
        cand.r_from = s_.cell_radius;
      }
      // A segment that only touches the view space at a surface point gives no direction.
      const double len = glm::length(cand.to - cand.from);
      if (len > 1e-6 && std::isfinite(len)) out.candidates.push_back(cand);
    };
    if (c_fwd > 0) add_candidate(true);
    if (c_rev > 0) add_candidate(false);
  }

  // Where `cell`, if it keeps witnesses, would see the object at parameter t_obj: the ray from
  // the sample's point at parameter t (inside the cell) to it.
  uint32_t WitnessOf(CellId cell, const Sample& smp, double t, double t_obj) {
    if (!s_.witness_cell[cell]) return kNoWitness;
    out_->witnesses.push_back({s_.frame + smp.origin + t * smp.dir, s_.frame + smp.origin + t_obj * smp.dir});
    return static_cast<uint32_t>(out_->witnesses.size() - 1);
  }

 private:
  const Impl& s_;
  const ViewcellGrid& grid_;
  const GlobalPvs& pvs_;
  const AgvsOptions& options_;
  ChunkResult* out_ = nullptr;
  Counts* counts_ = nullptr;                     // this thread's samples per cell and object, if counted
  std::vector<std::pair<double, double>> fan_;   // the silhouette search's scratch
  std::vector<Candidate> candidates_;            // this chunk's, gathered
  std::vector<FanSurface::Hot> fans_;              // where their objects' surfaces lie
  std::vector<Ahead> ahead_;                       // SurfaceChunk's draws
  std::vector<double> xs_;                         // their columns, scaled
  std::vector<uint32_t> picks_;                    // the entries those pick
  std::vector<std::pair<CellId, double>> walk_;    // Emit's cells along a segment

 public:
  void CountInto(Counts* counts) { counts_ = counts; }
};

}  // namespace

void GlobalSampler::RunBatch() {
  const auto start = std::chrono::steady_clock::now();
  Impl& m = *impl_;
  m.Commit();

  const Mixture mixture = PlanMixture(m, options_);
  const std::vector<Distribution>& available = mixture.available;
  const std::array<double, kDistributionCount>& share = mixture.share;
  const std::vector<uint32_t>& quota = mixture.quota;
  for (Distribution d : available) stats_.distributions[static_cast<size_t>(d)].probability = share[static_cast<size_t>(d)];

  const uint64_t batch = stats_.batches;
  std::vector<ChunkPlan> plans;
  Rng take_rng(Mix(options_.seed, Mix(batch, 0xb0ffe7)));
  for (Distribution d : available) {
    for (uint32_t q = 0; q < quota[static_cast<size_t>(d)]; ++q) {
      ChunkPlan plan{d, {}};
      if (d == Distribution::kTwoPointMutation || d == Distribution::kSilhouetteMutation) {
        plan.candidates.reserve(kChunk);
        for (uint32_t i = 0; i < kChunk; ++i) plan.candidates.push_back(m.buffer.Take(take_rng));
        // The buffer is not changed again until the chunks have been cast.
      }
      plans.push_back(std::move(plan));
    }
  }

  // Draw and cast in parallel; the sets are only read.
  std::vector<ChunkResult> results(plans.size());
  std::mutex counts_mutex;
  std::vector<std::unique_ptr<Counts>> counts;  // per thread
  ParallelFor(plans.size(), options_.threads, [&] {
    Worker worker(m, grid_, pvs_, options_);
    {
      const std::lock_guard lock(counts_mutex);
      counts.push_back(std::make_unique<Counts>());
      counts.back()->cells.assign(grid_.CellCount(), 0);
      counts.back()->objects.assign(m.objects.size(), 0);
      worker.CountInto(counts.back().get());
    }
    return [&, worker](size_t c) mutable { worker.Run(plans[c], Mix(options_.seed, Mix(batch, c)), &results[c]); };
  });

  for (const auto& per_thread : counts) {
    for (CellId c = 0; c < grid_.CellCount(); ++c) m.cell_samples[c] += per_thread->cells[c];
    for (ObjectId o = 0; o < m.objects.size(); ++o) m.object_hits[o] += per_thread->objects[o];
  }

  // Apply in chunk order.
  std::array<uint64_t, kDistributionCount> contribution{}, cost{}, drawn{};
  uint64_t est_rays = 0, est_hits = 0;
  for (size_t c = 0; c < plans.size(); ++c) {
    const ChunkResult& r = results[c];
    const auto k = static_cast<size_t>(plans[c].dist);
    for (const NewEntry& e : r.entries) {
      if (!pvs_.Insert(e.cell, e.object)) continue;
      ++stats_.entries;
      if (e.witness != kNoWitness) m.witnesses.emplace(uint64_t{e.cell} << 32 | e.object, r.witnesses[e.witness]);
    }
    for (const Candidate& cand : r.candidates) m.buffer.Add(cand);
    contribution[k] += r.contribution;
    cost[k] += r.embree_rays + r.silhouette_searches;  // a search costs about a ray
    drawn[k] += r.samples;
    stats_.samples += r.samples;
    stats_.rays += r.embree_rays;
    stats_.discarded_samples += r.discarded;
    est_rays += r.estimator_rays;
    est_hits += r.estimator_hits;
  }
  for (size_t k = 0; k < kDistributionCount; ++k) {
    DistributionStats& d = stats_.distributions[k];
    d.samples += drawn[k];
    d.rays += cost[k];
    d.contribution += contribution[k];
    if (drawn[k] > 0) {
      // Half-life of one batch: the window is about the last two batches.
      m.ema_contribution[k] = 0.5 * m.ema_contribution[k] + static_cast<double>(contribution[k]);
      m.ema_cost[k] = 0.5 * m.ema_cost[k] + static_cast<double>(cost[k]);
    }
  }

  m.estimator_window.emplace_back(est_rays, est_hits);
  UpdateEstimate(m, options_, &stats_);
  stats_.mutation_candidates = m.buffer.size();
  ++stats_.batches;
  stats_.seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

void GlobalSampler::RecordWitnesses(std::span<const CellId> cells) {
  for (CellId c : cells) {
    if (c < impl_->witness_cell.size()) impl_->witness_cell[c] = true;
  }
}

std::optional<Witness> GlobalSampler::WitnessOf(CellId cell, scenes::ObjectId object) const {
  const auto it = impl_->witnesses.find(uint64_t{cell} << 32 | object);
  if (it == impl_->witnesses.end()) return std::nullopt;
  return it->second;
}

std::vector<BoxHit> GlobalSampler::SampleFromBox(const scenes::Aabb& box, size_t rays, uint64_t seed) const {
  Worker w(*impl_, grid_, pvs_, options_);
  return w.FromBox(box, rays, seed);
}

}  // namespace vistream::visibility
