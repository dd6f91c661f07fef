#!/usr/bin/env python3
"""Paired comparison of tube pose files from the same detections (diagnostics for tubeloc refine).

`tubeloc eval` matches each pose file to the truths on its own (nearest centre within 50 mm), so
seeds and refined poses are compared on different tubes. Here the k-th pose of every file comes
from the k-th detection: each detection of REFERENCE (usually the seeds) is matched to the nearest
true tube of its image (centre within 100 mm, truths with visible_fraction >= 0.5) and every file
is scored on those same pairs: medians / p90 of the axis angle (deg), the centre's distance to the
true axis (perp, mm), along it (mm), the centre error (mm), the axis tilt error toward the camera
and the in-image axis error (deg), and the fraction of right ends.
Usage: paired_eval.py annotations.json REFERENCE.json [poses.json ...]   (numpy)
"""
import json,sys,numpy as np
gt=json.load(open(sys.argv[1])); S=json.load(open(sys.argv[2]))
anns={}
for a in gt['annotations']:
    if a.get('visible_fraction',1)<0.5 or 'T_cam_tube' not in a: continue
    T=a['T_cam_tube'];R=np.array(T['rotation']);anns.setdefault(a['image_id'],[]).append((np.array(T['translation']),R[:,2],a))
def err(p,t,a):
    c=np.array(p['centre']);ax=np.array(p['end_direction']);ax/=np.linalg.norm(ax)
    ray=t/np.linalg.norm(t);d=c-t
    perp=np.linalg.norm(d-a*(d@a)); along=abs(d@a)
    ends= ax@a>0
    if ax@a<0: ax=-ax
    ang=np.degrees(np.arccos(min(1,abs(ax@a))))
    tilt=abs(np.degrees(np.arcsin(ax@ray)-np.arcsin(a@ray)))
    def proj(v): v=v-ray*(v@ray); return v/np.linalg.norm(v)
    inpl=np.degrees(np.arccos(min(1,abs(proj(ax)@proj(a)))))
    return [ang,perp*1e3,along*1e3,np.linalg.norm(d)*1e3,tilt,inpl,ends,p['converged']]
match=[]
for i,s in enumerate(S):
    c=np.array(s['centre'])
    best=min(anns.get(s['image_id'],[]),key=lambda g:np.linalg.norm(g[0]-c),default=None)
    if best is None or np.linalg.norm(best[0]-c)>0.1: continue
    match.append((i,best))
names=['axis','perp','along','centre','tilt','inpl']
for f in sys.argv[2:]:
    P=json.load(open(f))
    r=np.array([err(P[i],t,a) for i,(t,a,_) in match],dtype=float)
    conv=r[:,7]>0
    s=f"{f.split('/')[-1]:>18} n={len(r)} conv={conv.sum()} "
    for k,nm in enumerate(names): s+=f"{nm} {np.median(r[:,k]):.2f}/{np.percentile(r[:,k],90):.2f} "
    s+=f"ends {100*r[:,6].mean():.0f}%"
    print(s)
