"""CampaignAnalysis: a campaign file's way to selected global modes, as :class:`~modaluq.analysis.Analysis`
is one record's.

The campaign (:func:`modaluq.io.load_campaign`, docs/multisetup.md) → :func:`~modaluq.identify_setups`
(the modular merge, docs/uq-math.md §13) → stabilization diagram → selected modes with global
shapes → provenance. ``modaluq identify --setups campaign.toml`` runs it; the results have the
types one record's have, so the same writers (:mod:`modaluq.export`, :mod:`modaluq.htmlreport`,
the UFF export) take them.
"""

from __future__ import annotations

import dataclasses
import warnings
from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from .analysis import describe_orders
from .checks import check_boolean, check_instance
from .identification import campaign_settings, identify_setups, make_settings
from .io import Campaign, load_campaign
from .preprocess import preprocess
from .provenance import provenance
from .results import ModalUQWarning, Result
from .selection import SelectedModes, largest_dropped_clusters, select_modes
from .settings import ClusteringSettings, PoleStatus, Settings, StabilityCriteria
from .spectrum import output_spectrum_singular_values
from .stabilization import Diagram, stabilization_diagram

__all__ = ["CampaignAnalysis"]


@dataclass
class CampaignAnalysis:
    """A campaign's way from its setups to selected global modes; :meth:`run` fills the results.

    Made by :meth:`from_file` (a campaign file) or :meth:`from_campaign`. ``settings`` are the
    campaign's ``[settings]`` with the keywords given replacing them.
    """

    campaign: Campaign
    references: tuple
    inputs: tuple = ()
    fs: Optional[float] = None
    settings: Settings = dataclasses.field(default_factory=Settings)
    criteria: StabilityCriteria = dataclasses.field(default_factory=StabilityCriteria)
    clustering: ClusteringSettings = dataclasses.field(default_factory=ClusteringSettings)
    # ------------------------------------------------------------------ filled by run()
    result: Optional[Result] = None
    diagram: Optional[Diagram] = None
    selected: Optional[SelectedModes] = None
    warnings: tuple = ()

    @classmethod
    def from_campaign(cls, campaign: Campaign, *, fs: float | None = None, references=None, inputs=None,
                      criteria: StabilityCriteria | None = None, clustering: ClusteringSettings | None = None,
                      **keywords) -> "CampaignAnalysis":
        """An analysis of ``campaign``; ``fs``, ``references``, ``inputs`` and the keywords of
        :func:`~modaluq.identify_setups` (``block_rows``, ``orders``, ``frequency_range``, ...)
        replace the campaign's."""
        check_instance("campaign", campaign, Campaign)
        settings = make_settings(campaign_settings(campaign), keywords, function="identify_setups")
        refs = campaign.references if references is None else tuple(str(r) for r in references)
        ins = campaign.inputs if inputs is None else tuple(str(c) for c in inputs)
        return cls(campaign=campaign, references=tuple(refs), inputs=tuple(ins),
                   fs=campaign.fs if fs is None else fs, settings=settings,
                   criteria=check_instance("criteria", criteria, StabilityCriteria),
                   clustering=check_instance("clustering", clustering, ClusteringSettings))

    @classmethod
    def from_file(cls, path, **kwargs) -> "CampaignAnalysis":
        """An analysis of the campaign file ``path`` (:func:`modaluq.io.load_campaign`); the
        keywords as for :meth:`from_campaign`."""
        return cls.from_campaign(load_campaign(path), **kwargs)

    @property
    def output_names(self) -> tuple:
        """The global DOFs: the references, then each setup's other outputs (after :meth:`run`;
        before, from the campaign's channels)."""
        if self.result is not None:
            return tuple(self.result.output_names)
        names = list(self.references)
        for rec in self.campaign.setups:
            names += [c for c in rec.output_names if c not in self.references and c not in self.inputs]
        return tuple(names)

    # ------------------------------------------------------------------ steps

    def run(self, *, progress: Callable[[str], None] | None = None,
            issue_warnings: bool = True) -> "CampaignAnalysis":
        """Identify the merged campaign, form the diagram, select the modes; returns self."""
        issue_warnings = check_boolean("issue_warnings", issue_warnings)
        step = progress or (lambda _: None)
        step("identifying")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # kept in result.warnings
            result = identify_setups(dataclasses.replace(self.campaign, settings={}), fs=self.fs,
                                     references=list(self.references), inputs=list(self.inputs) or None,
                                     settings=self.settings)
        self.result = result
        step("stabilization diagram")
        self.diagram = stabilization_diagram(result, self.criteria, output_names=result.output_names)
        step("clustering")
        self.selected = select_modes(self.diagram, self.clustering)
        self.warnings = tuple(result.warnings)
        if issue_warnings:
            for w in self.warnings:
                warnings.warn(w, ModalUQWarning, stacklevel=2)
        return self

    def spectrum(self, nperseg: int | None = None) -> tuple:
        """``(frequency_hz, singular_values)`` of the reference channels' spectral density matrix,
        each setup preprocessed as identified, averaged over the setups weighted by their lengths
        (the references are the channels every setup has). ``nperseg`` default: the rule of
        :func:`~modaluq.spectrum.output_spectrum_singular_values` for the shortest setup."""
        pre = []
        for rec in self.campaign.setups:
            names = list(rec.output_names) + list(rec.input_names)
            data = rec.y if rec.u is None else np.hstack([rec.y, rec.u])
            y = data[:, [names.index(r) for r in self.references]]
            p = preprocess(y, None, fs=rec.fs, **self.settings.preprocessing)
            pre.append((p.y, p.fs))
        shortest = min(y.shape[0] for y, _ in pre)
        if nperseg is None:
            nperseg = int(2 ** round(np.log2(max(shortest / 64, 1))))
            nperseg = min(max(nperseg, 256), 8192, shortest)
        nperseg = min(int(nperseg), shortest)
        total, acc, freq = 0, None, None
        for y, fs in pre:
            freq, sv = output_spectrum_singular_values(y, fs, nperseg=nperseg)
            acc = sv * y.shape[0] if acc is None else acc + sv * y.shape[0]
            total += y.shape[0]
        return freq, acc / total

    # ------------------------------------------------------------------ provenance and reports

    def provenance(self, **extra_settings) -> dict:
        """The stamp of the run: version, every setting, the channels, the campaign file's and
        every setup file's checksum."""
        self._require_run()
        stamp = provenance(self.campaign.source or None, settings={
            "identification": self.result.settings, "stability": self.criteria.to_dict(),
            "clustering": self.clustering.to_dict(),
            "channels": {"outputs": list(self.output_names), "inputs": list(self.inputs),
                         "references": list(self.references)},
            **extra_settings,
        })
        stamp["setup_files"] = [{"setup": name, **provenance(rec.source)["input_file"]} if rec.source else
                                {"setup": name} for name, rec in zip(self.campaign.names, self.campaign.setups)]
        return stamp

    def report(self) -> dict:
        """What a report adds to the diagram and the modes: the campaign and the warnings."""
        self._require_run()
        return {"input": {"campaign": self.campaign.source or None, "fs_hz": float(self.campaign.setups[0].fs),
                          "references": list(self.references), "inputs": list(self.inputs),
                          "outputs": list(self.output_names),
                          "setups": [{"name": name, "source": rec.source or None, "n_samples": rec.n_samples,
                                      "channels": list(rec.output_names) + list(rec.input_names)}
                                     for name, rec in zip(self.campaign.names, self.campaign.setups)]},
                "warnings": list(self.warnings)}

    def describe_run(self) -> str:
        """The setups, the settings chosen and the diagram's counts, in words."""
        self._require_run()
        r, d, s = self.result, self.diagram, self.result.settings
        kind = "input/output" if r.n_inputs else "output-only"
        recs = self.campaign.setups
        lines = [f"  {len(recs)} setups at {recs[0].fs:g} Hz, {kind}; references: {', '.join(self.references)}"
                 + (f"; inputs: {', '.join(self.inputs)}" if self.inputs else "")
                 + f"; {len(self.output_names)} global DOFs"]
        for name, rec in zip(self.campaign.names, recs):
            chans = [c for c in list(rec.output_names) + list(rec.input_names) if c not in self.references]
            lines.append(f"    {name}: {rec.n_samples} samples ({rec.duration:g} s), {', '.join(chans)}")
        lines += [f"  chosen: {why}" for why in s.get("chosen", [])]
        lines.append(f"  block_rows={s['block_rows']}, past_block_rows={s['past_block_rows']}, "
                     f"orders {describe_orders(r.orders)}, "
                     + (f"{s['n_blocks']} blocks per setup" if r.n_blocks else "no uncertainty"))
        counts = ", ".join(f"{st.value.replace('_', ' ')} {d.count(st)}" for st in PoleStatus)
        lines.append(f"  stabilization diagram: {d.n_poles} poles ({counts})")
        return "\n".join(lines)

    def describe_modes(self) -> str:
        """The selected modes and the largest dropped clusters."""
        self._require_run()
        sel = self.selected
        if sel.n_modes:
            lines = [str(sel)]
        else:
            lines = ["no mode selected: no cluster of stable poles both reached "
                     f"{sel.min_cluster_size} poles and had a frequency std within its bandwidth "
                     "(try more orders, longer setups, a narrower band or looser criteria)"]
        lines += largest_dropped_clusters(sel)
        return "\n".join(lines)

    def __str__(self) -> str:
        if self.result is None:
            return repr(self)
        return self.describe_run() + "\n\n" + self.describe_modes()

    def __repr__(self) -> str:
        state = "not run" if self.result is None else f"{self.selected.n_modes} modes selected"
        return (f"CampaignAnalysis({self.campaign.source or 'campaign'}: {len(self.campaign.setups)} setups, "
                f"references {list(self.references)}; {state})")

    def _require_run(self) -> None:
        if self.result is None:
            raise ValueError("the analysis has not been run: call .run() first")
