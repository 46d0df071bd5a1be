"""Progress bar (tqdm) with samples/s and an ETA, in samples per pixel or seconds."""
import sys


class Progress:
    def __init__(self, spp, time_limit, pixels, quiet=False, stream=sys.stderr, start_spp=0):
        """``start_spp``: the samples per pixel a resumed render starts from."""
        self.spp = spp
        self.start_spp = start_spp
        self.time_limit = time_limit
        self.pixels = pixels
        self.bar = None
        self.stream = stream
        if not quiet:
            from tqdm import tqdm
            by_time = spp is None
            self.bar = tqdm(total=time_limit if by_time else spp,
                            unit="s" if by_time else "spp", file=stream, dynamic_ncols=True,
                            initial=0 if by_time else start_spp,
                            bar_format="{l_bar}{bar}| {n:.4g}/{total_fmt} {unit} "
                                       "[{elapsed}<{remaining}{postfix}]")
        self.by_time = spp is None

    def start_sampling(self):
        """Start the bar's clock now (the kernels are ready): its rate and ETA count
        sampling time only, not the compile before it."""
        if self.bar is not None:
            now = self.bar._time()
            self.bar.start_t = self.bar.last_print_t = now
            self.bar.last_print_n = self.bar.n
            self.bar.refresh()

    def update(self, spp, elapsed):
        if self.bar is None:
            return
        self.bar.n = min(elapsed, self.time_limit) if self.by_time else spp
        rate = (spp - self.start_spp) * self.pixels / max(elapsed, 1e-9)
        self.bar.set_postfix_str(f"{spp} spp, {rate / 1e6:.2f} M samples/s", refresh=False)
        self.bar.refresh()

    def write(self, text):
        if self.bar is not None:
            self.bar.write(text, file=self.stream)
        else:
            print(text, file=self.stream)

    def close(self):
        if self.bar is not None:
            self.bar.close()
