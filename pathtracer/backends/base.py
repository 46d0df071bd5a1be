"""The backend protocol: what the progressive loop (progressive.render) and the API call on
every backend, with the defaults of a backend that renders one pass at a time.

CPU (backends.cpu), CUDA (backends.cuda: the megakernel or the wavefront, as
kernels.drivers.choose_driver picks), interpreted Python (backends.python) and the split
backend of several devices or Ray workers (distribute.SplitBackend) implement it. A backend
holds one compiled scene (``scene``); ``update`` swaps in another of the same features and
size (the API's re-render), ``compile`` compiles or loads its kernels, and a pass renders
samples [sample_start, sample_start + n_samples) of every pixel (of those where ``active``,
uint8 H x W, is not 0: adaptive sampling).
"""

# Paths in the first pass of a render without a callback, per backend kind: large enough that
# a small GPU re-render is one launch and that the passes of a large one do not start at a
# few ms of work (each pass costs a launch, a copy and the film's sum: ~8 ms for a 1024^2
# image on an H200, measured 2026-11-24), small enough that Ctrl-C is answered within a
# fraction of a second (2^23 paths: ~10-30 ms on an H100). A split render's workers take
# this each (distribute.SplitBackend.first_pass_paths).
FIRST_PASS_PATHS = {"cuda": 1 << 23, "cpu": 1 << 17}


class Backend:
    """The protocol, with defaults. Subclasses implement ``update``, ``compile``,
    ``render_pass`` and ``aovs``; the rest they override where they can do better."""
    name = ""
    # seconds a progressive pass aims at (progressive.render grows or shrinks passes to it)
    pass_seconds = 0.5
    # whether ``launch`` starts a pass without waiting for it (``collect_pass_totals`` then
    # waits): the progressive loop launches the next pass before it adds this one
    pipelined = False

    @property
    def first_pass_paths(self):
        """Paths a first pass may take when nobody sees the intermediate images."""
        return FIRST_PASS_PATHS.get(self.name, 0)

    def update(self, scene):
        """Render ``scene`` from now on (the same features and image size: nothing is
        compiled)."""
        raise NotImplementedError

    def compile(self):
        """Compile (or load from the disk cache) the kernels without rendering."""
        raise NotImplementedError

    def render_pass(self, sample_start, n_samples, seed, max_bounces, rr_depth, active=None):
        """(sums over the pass's paths per pixel, float H x W x 3; ray and non-finite
        counts, layout STAT_*, H x W x 3 or their totals 1 x 1 x 3). The arrays may be
        buffers that the next pass reuses."""
        raise NotImplementedError

    def render_pass_totals(self, sample_start, n_samples, seed, max_bounces, rr_depth,
                           active=None):
        """render_pass, its counts possibly as totals (1 x 1 x 3): the film only adds them
        up, and a backend that sums them itself (CUDA: on the GPU) saves the copy."""
        return self.render_pass(sample_start, n_samples, seed, max_bounces, rr_depth, active)

    def prepare_halves(self):
        """Get ready for render_halves (adaptive sampling)."""

    def render_halves(self, sample_start, half, seed, max_bounces, rr_depth, active=None):
        """The two halves of an adaptive pass, samples [sample_start, + half) and the next
        ``half``, each as render_pass's answer; one after the other (a half's buffers are
        added to the film before the next half renders)."""
        for k in range(2):
            yield self.render_pass(sample_start + k * half, half, seed, max_bounces,
                                   rr_depth, active)

    def launch(self, sample_start, n_samples, seed, max_bounces, rr_depth, active=None):
        """Start a pass without waiting for it (where ``pipelined``)."""
        raise NotImplementedError(f"the {self.name} backend renders one pass at a time")

    def collect_pass_totals(self):
        """The launched pass's render_pass_totals answer, once it is done."""
        raise NotImplementedError(f"the {self.name} backend renders one pass at a time")

    def aovs(self, n_samples, seed):
        """The denoiser's albedo and normal images (float32 H x W x AOV_WIDTH)."""
        raise NotImplementedError

    def shares(self):
        """Each worker's share of the samples so far (split backends), else None."""
        return None
