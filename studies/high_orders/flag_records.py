"""Per-pole frozen and plain sigma of the same records (seed 0, as modaluq validate), for choosing
rho_max: python3 flag_records.py N OUT.npy UNKNOWN_INPUT_STD N_BLOCKS DAMPING LIMIT FREEZE(0/1).
Run once with LIMIT 1e300 FREEZE 1 (frozen everywhere) and once with FREEZE 0 (plain); then
python3 flag_threshold.py FROZEN.npy PLAIN.npy 5,10,20.  docs/validation.md, issue 11."""
import sys
import warnings
from multiprocessing import Pool

import numpy as np

import modaluq
from modaluq.validation import match_modes

N=int(sys.argv[1])
out=sys.argv[2]
uis=float(sys.argv[3])
nb=int(sys.argv[4])
xi=float(sys.argv[5])
lim=float(sys.argv[6])
frz=sys.argv[7]=='1'
ORD=[12,18,24,36]
def rec(k):
    warnings.simplefilter("ignore")
    sim=modaluq.simulate(10_000, seed=np.random.SeedSequence(0, spawn_key=(k,)), unknown_input_std=uis, damping_ratio=xi)
    res=np.full((2,len(ORD),6,6),np.nan)  # f, xi, sf, sxi, coupled, rho
    for m,u in enumerate((None, sim.u)):
        r=modaluq.identify(sim.y,u,fs=sim.fs,block_rows=15,orders=ORD,n_blocks=nb,noise_coupling_limit=lim,freeze_noise=frz)
        for j,n in enumerate(ORD):
            md=r.at_order(n)
            idx=match_modes(md.frequency_hz, sim.frequency_hz)
            h=idx>=0
            for c,arr in enumerate((md.frequency_hz,md.damping_ratio,md.frequency_std,md.damping_std,md.noise_coupled.astype(float),md.noise_coupling)):
                res[m,j,h,c]=arr[idx[h]]
    return res, sim.frequency_hz
if __name__=="__main__":
    with Pool(2) as p:
        rs=p.map(rec, range(N), chunksize=10)
    R=np.stack([r[0] for r in rs],axis=2)  # (2, nord, N, 6, 6)
    np.save(out,R)
