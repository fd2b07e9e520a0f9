"""Spurious (unmatched) poles above the true order: share flagged noise_coupled and share with
sigma_f/f > 2 % for rho_max = 5, 10, 20 (40 records, paper case).
usage: python3 flag_spurious.py [N_RECORDS]  docs/validation.md, issue 11."""
import sys
import warnings

import numpy as np

import modaluq
from modaluq.validation import match_modes

warnings.simplefilter("ignore")
ORD=[18,24,36]
acc={}
for k in range(int(sys.argv[1]) if len(sys.argv) > 1 else 40):
    sim=modaluq.simulate(10_000, seed=np.random.SeedSequence(0, spawn_key=(k,)))
    for m,u in enumerate((None,sim.u)):
        rf=modaluq.identify(sim.y,u,fs=sim.fs,block_rows=15,orders=ORD,noise_coupling_limit=1e300)
        rb=modaluq.identify(sim.y,u,fs=sim.fs,block_rows=15,orders=ORD,freeze_noise=False)
        for n in ORD:
            a=rf.at_order(n)
            b=rb.at_order(n)
            idx=match_modes(a.frequency_hz, sim.frequency_hz)
            sp=np.ones(a.n_modes,bool)
            sp[idx[idx>=0]]=False
            d=acc.setdefault((m,n),[])
            for i in np.flatnonzero(sp):
                d.append((a.noise_coupling[i], a.frequency_std[i]/a.frequency_hz[i], b.frequency_std[i]/b.frequency_hz[i]))
for (m,n),d in sorted(acc.items()):
    d=np.array(d)
    rho=d[:,0]
    for T in (5,10,20):
        rep=np.where(rho>T,d[:,2],d[:,1])
        print(("OO","IO")[m],n,"T",T,"spurious",len(d),"flagged %.0f%%"%(100*np.mean(rho>T)),"sigma_f/f>2%% (reported) %.0f%%"%(100*np.mean(rep>0.02)), "flagged or >2%%: %.0f%%"%(100*np.mean((rho>T)|(rep>0.02))), "base>2%%: %.0f%%"%(100*np.mean(d[:,2]>0.02)))
