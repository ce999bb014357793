"""Occupancy never skips an occupied cell; samples lie on the rays inside the box;
projection inverts ray generation."""

import math

import torch

from renderer import (
    GridField,
    Intrinsics,
    OccupancyGrid,
    camera_rays,
    intersect_aabb,
    look_at,
    project_points,
    sample_along_rays,
)

AABB = torch.tensor([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])


def test_occupancy_never_skips_an_occupied_cell():
    g = torch.Generator().manual_seed(0)
    field = GridField(AABB, resolution=12, step_m=0.05)
    with torch.no_grad():
        field.density_grid.fill_(-10.0)
        # a few isolated dense vertices, one on the box edge
        for z, y, x in [(3, 4, 5), (7, 7, 1), (0, 11, 11), (5, 5, 5)]:
            field.density_grid[0, 0, z, y, x] = 40.0
    occ = OccupancyGrid.for_grid_field(field)
    threshold = 1e-3
    frac = occ.update(field.density, 0.05, threshold, vertex_density=field.vertex_density())
    assert 0.0 < frac < 0.5
    points = torch.rand(400_000, 3, generator=g) * 2 - 1
    alpha = 1 - torch.exp(-field.density(points) * 0.05)
    occupied_points = alpha > threshold
    assert occupied_points.sum() > 1000
    assert occ.query(points)[occupied_points].all()
    # the generic path (density_fn only, at corners and centres) agrees on this field
    occ2 = OccupancyGrid(AABB, (11, 11, 11))
    occ2.update(field.density, 0.05, threshold)
    assert torch.equal(occ2.occupied, occ.occupied)


def test_query_is_false_outside_the_box():
    occ = OccupancyGrid(AABB, (4, 4, 4))
    pts = torch.tensor([[0.0, 0.0, 0.0], [1.01, 0.0, 0.0], [0.0, -1.5, 0.0], [1.0, 1.0, 1.0]])
    assert occ.query(pts).tolist() == [True, False, False, True]


def test_samples_lie_on_rays_inside_the_box_at_step_spacing():
    o = torch.tensor([[0.0, 0.0, 3.0], [0.0, 0.0, 3.0], [5.0, 5.0, 5.0]])
    d = torch.tensor([[0.0, 0.0, -1.0], [0.6, 0.0, -0.8], [1.0, 0.0, 0.0]])
    t_near, t_far = intersect_aabb(o, d, AABB)
    assert math.isclose(t_near[0].item(), 2.0) and math.isclose(t_far[0].item(), 4.0)
    assert t_far[2] <= t_near[2]  # misses
    s = sample_along_rays(o, d, AABB, 0.1)
    assert s.ray_indices.tolist() == sorted(s.ray_indices.tolist()) and 2 not in s.ray_indices
    assert (s.ray_indices == 0).sum() == 20  # 2 m at 0.1 m, midpoints
    assert torch.allclose(
        s.positions, o[s.ray_indices] + s.t[:, None] * d[s.ray_indices], atol=1e-6
    )
    assert (s.positions.abs() <= 1 + 1e-6).all()
    t0 = s.t[s.ray_indices == 0]
    assert torch.allclose(t0[1:] - t0[:-1], torch.full((19,), 0.1), atol=1e-5)
    assert math.isclose(t0[0].item(), 2.05, abs_tol=1e-5)


def test_project_points_inverts_camera_rays():
    pose = look_at(torch.tensor([2.0, -3.0, 1.5]), torch.tensor([0.1, 0.2, 0.0]))
    intr = Intrinsics(30.0, 28.0, 9.5, 7.0, 14, 20)
    o, d = camera_rays(pose[None], intr)
    pts = o[0] + 2.5 * d[0]
    uv, z = project_points(pts, pose, intr)
    v, u = torch.meshgrid(torch.arange(14.0), torch.arange(20.0), indexing="ij")
    assert torch.allclose(uv, torch.stack([u + 0.5, v + 0.5], -1), atol=1e-4)
    assert (z > 0).all()
    # the centre ray looks along -z of the pose
    assert torch.allclose(
        camera_rays(pose[None], Intrinsics(1.0, 1.0, 0.5, 0.5, 1, 1))[1][0, 0, 0],
        -pose[:3, 2],
        atol=1e-6,
    )


def test_carving_keeps_every_cell_the_object_touches_and_empties_the_rest():
    # exact silhouettes of a sphere of radius 0.4 at (0.1, -0.2, 0.05), seen from 20 views
    centre, radius = torch.tensor([0.1, -0.2, 0.05]), 0.4
    poses = torch.cat(
        [
            torch.stack([look_at(torch.tensor(e), torch.zeros(3)) for e in eyes])
            for eyes in [
                [
                    [
                        3.0 * math.cos(a) * math.cos(el),
                        3.0 * math.sin(a) * math.cos(el),
                        3.0 * math.sin(el),
                    ]
                    for a in torch.linspace(0, 2 * math.pi, 11)[:-1].tolist()
                ]
                for el in (0.35, -0.4)
            ]
        ]
    )
    intr = Intrinsics(40.0, 40.0, 24.0, 24.0, 48, 48)
    o, d = camera_rays(poses, intr)
    oc = o - centre
    b = (oc * d).sum(-1)
    hit = b * b - ((oc * oc).sum(-1) - radius**2) > 0
    masks = hit.float()  # [views, h, w]

    occ = OccupancyGrid(AABB, (20, 20, 20))
    frac_free = occ.carve(poses, intr, masks)
    # cells whose box comes within the radius of the centre hold part of the sphere
    lo = occ._lattice(0.0)[:-1, :-1, :-1]
    hi = occ._lattice(0.0)[1:, 1:, 1:]
    nearest = torch.maximum(torch.minimum(centre, hi), lo)  # closest point of each cell box
    touches = (nearest - centre).norm(dim=-1) <= radius
    assert touches.sum() > 50
    assert not occ.free[touches].any(), "a cell holding the sphere was carved"
    assert occ.occupied[touches].all()
    # far from the sphere almost everything the cameras see is carved
    far = (occ._lattice(0.5) - centre).norm(dim=-1) > radius + 0.35
    assert occ.free[far].float().mean() > 0.8
    assert 0.5 < frac_free < 1.0
    # a finer grid inherits the free space without carving again, and never more
    fine = OccupancyGrid(AABB, (33, 33, 33))
    assert fine.inherit_free(occ) > 0.3
    flo, fhi = fine._lattice(0.0)[:-1, :-1, :-1], fine._lattice(0.0)[1:, 1:, 1:]
    fine_touches = (torch.maximum(torch.minimum(centre, fhi), flo) - centre).norm(dim=-1) <= radius
    assert fine.occupied[fine_touches].all()
    fine_far = (fine._lattice(0.5) - centre).norm(dim=-1) > radius + 0.5
    assert fine.free[fine_far].float().mean() > 0.6
    # updates from a (foggy) density field never bring carved cells back
    occ.update(lambda p: torch.full((p.shape[0],), 5.0), 0.05)
    assert not (occ.occupied & occ.free).any()
    assert occ.occupied[touches].all()


def test_a_finer_grid_inherits_exactly_the_free_space_of_a_coarser_one():
    coarse = OccupancyGrid(AABB, (4, 4, 4))  # cells of 0.5 m
    coarse.free[:] = True
    coarse.free[1, 2, 1] = False  # x in [-0.5, 0], y in [0, 0.5], z in [-0.5, 0]
    fine = OccupancyGrid(AABB, (7, 7, 7))  # not aligned with the coarse cells
    fine.inherit_free(coarse)
    lo, hi = fine._lattice(0.0)[:-1, :-1, :-1], fine._lattice(0.0)[1:, 1:, 1:]
    box_lo, box_hi = torch.tensor([-0.5, 0.0, -0.5]), torch.tensor([0.0, 0.5, 0.0])
    overlaps = ((lo < box_hi) & (hi > box_lo)).all(dim=-1)
    assert overlaps.sum() >= 8
    assert not fine.free[overlaps].any(), "a cell overlapping occupied space was freed"
    assert fine.occupied[overlaps].all()
    # cells two fine cells away from the occupied box are freed
    gap = 2 * 2.0 / 7
    far = ((lo > box_hi + gap) | (hi < box_lo - gap)).any(dim=-1)
    assert fine.free[far].all()


def test_sh_basis_is_orthonormal_on_the_sphere():
    from renderer.fields import sh_basis

    g = torch.Generator().manual_seed(0)
    d = torch.nn.functional.normalize(torch.randn(400_000, 3, generator=g), dim=-1)
    y = sh_basis(d, 2)
    y[:, 0] = 0.5 / math.sqrt(math.pi)  # the true Y_0 (the field uses 1 so DC is a logit)
    gram = 4 * math.pi * (y.T @ y) / d.shape[0]  # Monte-Carlo integral over the sphere
    assert torch.allclose(gram, torch.eye(9), atol=0.02)


def test_adding_view_dependence_keeps_the_field_and_then_depends_on_direction():
    g = torch.Generator().manual_seed(0)
    field = GridField(AABB, resolution=8, step_m=0.05)
    with torch.no_grad():
        field.color_grid.normal_(generator=g)
    pts = torch.rand(100, 3, generator=g) * 2 - 1
    dirs = torch.nn.functional.normalize(torch.randn(100, 3, generator=g), dim=-1)
    _, before = field(pts, dirs)
    field.set_sh_degree(1)
    assert field.sh_degree == 1 and field.color_grid.shape[1] == 12
    _, after = field(pts, dirs)
    assert torch.allclose(before, after, rtol=0.0, atol=1e-6)  # float rounding of the reads
    with torch.no_grad():
        field.color_grid[:, 1:4] = 1.0  # red's degree-1 coefficients (channels are [3, K])
    _, a = field(pts, dirs)
    _, b = field(pts, -dirs)
    assert (a[:, 0] - b[:, 0]).abs().max() > 0.05 and torch.equal(a[:, 1:], b[:, 1:])


def test_trilinear_gathers_equal_grid_sample_in_value_and_gradient():
    """The field's reads are grid_sample's (align_corners, border) up to rounding: inside
    the box, on its faces and corners, and outside it (clamped), for grids of 2 vertices."""
    from renderer.fields import trilinear

    g = torch.Generator().manual_seed(0)
    aabb = torch.tensor([[-1.0, -0.5, 0.2], [1.5, 0.7, 1.0]])
    for shape in ((2, 2, 2), (5, 7, 3), (17, 9, 12)):
        grid = torch.randn(1, 4, *shape, generator=g)
        pts = aabb[0] + (aabb[1] - aabb[0]) * (torch.rand(3000, 3, generator=g) * 1.4 - 0.2)
        pts[:2] = aabb  # the two corners
        a = grid.clone().requires_grad_(True)
        b = grid.clone().requires_grad_(True)
        ref = (
            torch.nn.functional.grid_sample(
                a,
                ((pts - aabb[0]) / (aabb[1] - aabb[0]) * 2 - 1).reshape(1, 1, 1, -1, 3),
                align_corners=True,
                padding_mode="border",
            )
            .reshape(4, -1)
            .t()
        )
        out = trilinear(b, aabb, pts)
        assert torch.allclose(out, ref, atol=1e-5)
        upstream = torch.randn(out.shape, generator=g)
        (ref * upstream).sum().backward()
        (out * upstream).sum().backward()
        assert torch.allclose(b.grad, a.grad, atol=1e-4)


def test_inference_reads_of_vertex_rows_equal_the_training_reads_and_follow_updates():
    """read_rows (embedding_bag over a vertex-major copy) gives read_corners' values; the
    copy is rebuilt after an in-place update and after the grid is replaced; a field
    renders the same with and without gradients."""
    from renderer.fields import VertexRows, read_corners, read_rows, trilinear_corners

    g = torch.Generator().manual_seed(1)
    aabb = torch.tensor([[-1.0, -0.5, 0.2], [1.5, 0.7, 1.0]])
    grid = torch.nn.Parameter(torch.randn(1, 6, 7, 5, 9, generator=g))
    pts = aabb[0] + (aabb[1] - aabb[0]) * torch.rand(500, 3, generator=g)
    corners = trilinear_corners(aabb, grid.shape[2:], pts)
    rows = VertexRows()
    assert torch.allclose(read_rows(rows(grid), *corners), read_corners(grid, *corners), atol=1e-5)
    with torch.no_grad():
        grid.mul_(-2.0)  # in place, as an optimiser step does
    assert torch.allclose(read_rows(rows(grid), *corners), read_corners(grid, *corners), atol=1e-5)
    other = torch.randn(1, 6, 7, 5, 9, generator=g)
    assert torch.allclose(
        read_rows(rows(other), *corners), read_corners(other, *corners), atol=1e-5
    )
    one = torch.randn(1, 1, 7, 5, 9, generator=g)  # one channel: the grid itself, no copy
    assert rows(one).data_ptr() == one.data_ptr()

    field = GridField(AABB, resolution=9)
    with torch.no_grad():
        field.density_grid.normal_(generator=g)
        field.set_sh_degree(1)
        field.color_grid.normal_(generator=g)
    p = torch.rand(300, 3, generator=g) * 2 - 1
    d = torch.nn.functional.normalize(torch.randn(300, 3, generator=g), dim=-1)
    sigma, rgb = field(p, d)
    with torch.no_grad():
        sigma0, rgb0 = field(p, d)
        dens0 = field.density(p)
    assert torch.allclose(sigma0, sigma, rtol=1e-5) and torch.allclose(rgb0, rgb, atol=1e-6)
    assert torch.allclose(dens0, sigma, rtol=1e-5)
    outside = torch.cat([p * 1.7, AABB.float()])  # the border beyond the box, its corners
    field.eval()
    with torch.no_grad():  # in eval mode without gradients: the fused read
        fused = field.density(outside)
    assert torch.allclose(fused, field.density(outside), rtol=1e-5)  # with them: the gathers
    field.train()

    # a fused optimiser step does not move the grid's version counter: the copy made in
    # eval mode must not survive the switch to training and back
    field.eval()
    with torch.no_grad():
        before = field(p, d)[1]
    field.train()
    opt = torch.optim.Adam(field.parameters(), lr=0.5, fused=True)
    field(p, d)[1].sum().backward()
    opt.step()
    field.eval()
    with torch.no_grad():
        after = field(p, d)[1]
    with torch.enable_grad():
        want = field(p, d)[1].detach()
    assert not torch.allclose(after, before, atol=1e-3)
    assert torch.allclose(after, want, atol=1e-6)


def test_occupancy_along_rays_equals_a_lookup_by_hand():
    """The sampler's cell-unit test (query_along) keeps exactly the points whose cell,
    found by hand in world units (floor of the position over the cell size, nothing
    outside the box), is occupied, with and without the promise that every point lies in
    the box; ``query`` (which is built on it) agrees."""
    g = torch.Generator().manual_seed(2)
    occ = OccupancyGrid(AABB, (6, 5, 7))
    occ.occupied = torch.rand(occ.occupied.shape, generator=g) > 0.6
    o = torch.randn(40, 3, generator=g) * 3
    d = torch.nn.functional.normalize(torch.randn(40, 3, generator=g), dim=-1)
    ray = torch.randint(0, 40, (4000,), generator=g)
    t = torch.rand(4000, generator=g) * 6
    pts = o[ray] + t[:, None] * d[ray]
    nx, ny, nz = occ.cells
    size = torch.tensor([nx, ny, nz], dtype=torch.float32)
    rel = (pts - AABB[0]) / (AABB[1] - AABB[0]) * size  # cell units, x y z
    in_box = ((rel >= 0) & (rel < size)).all(-1)
    cell = rel.floor().long().clamp(min=0)
    cell = torch.minimum(cell, size.long() - 1)
    hit = in_box & occ.occupied[cell[:, 2], cell[:, 1], cell[:, 0]]
    want = hit.nonzero()[:, 0]
    assert 0 < want.numel() < in_box.sum()  # some points in occupied cells, some in empty
    assert torch.equal(occ.query_along(o, d, ray, t, inside_only=False), want)
    assert torch.equal(occ.query(pts).nonzero()[:, 0], want)
    inside = (pts.abs() < 0.999).all(-1)  # away from the faces, where rounding may differ
    sub = inside.nonzero()[:, 0]
    got = occ.query_along(o, d, ray[sub], t[sub], inside_only=True)
    assert torch.equal(sub[got], want[inside[want]])
