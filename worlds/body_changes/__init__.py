"""Generic body changes for any world served by our node: reverse, permute, gain, lesion, noise,
delay, restore (`kinds`), applied on the action channel (`motor`) and the observation channel
(`sensors`) by one wrapper layer (`layer.BodyChanges`); an environment's own kinds through its
``sme_perturb`` hook (`hook`); what a world takes, advertised in its spec (`advertise`)."""
