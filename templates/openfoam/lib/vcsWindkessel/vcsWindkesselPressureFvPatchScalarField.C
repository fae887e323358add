/*---------------------------------------------------------------------------*\
  vcsWindkesselPressure: see the header for the equations.
\*---------------------------------------------------------------------------*/

#include "vcsWindkesselPressureFvPatchScalarField.H"
#include "addToRunTimeSelectionTable.H"
#include "volFields.H"
#include "surfaceFields.H"

// * * * * * * * * * * * * * * * * Constructors  * * * * * * * * * * * * * * //

Foam::vcsWindkesselPressureFvPatchScalarField::
vcsWindkesselPressureFvPatchScalarField
(
    const fvPatch& p,
    const DimensionedField<scalar, volMesh>& iF
)
:
    mixedFvPatchScalarField(p, iF),
    Rp_(0),
    C_(0),
    Rd_(0),
    Pd_(0),
    Pc_(0),
    tState_(0),
    timeIndex_(-1),
    phiName_("phi"),
    rAUName_(word::null),
    implicit_(false),
    warnedExplicit_(false)
{
    refValue() = Zero;
    refGrad() = Zero;
    valueFraction() = 1.0;
}


Foam::vcsWindkesselPressureFvPatchScalarField::
vcsWindkesselPressureFvPatchScalarField
(
    const fvPatch& p,
    const DimensionedField<scalar, volMesh>& iF,
    const dictionary& dict
)
:
    mixedFvPatchScalarField(p, iF),
    Rp_(readScalar(dict.lookup("Rp"))),
    C_(readScalar(dict.lookup("C"))),
    Rd_(readScalar(dict.lookup("Rd"))),
    Pd_(dict.lookupOrDefault<scalar>("Pd", 0)),
    Pc_(dict.lookupOrDefault<scalar>("Pc", 0)),
    tState_(dict.lookupOrDefault<scalar>("tState", iF.time().value())),
    timeIndex_(-1),
    phiName_(dict.lookupOrDefault<word>("phi", "phi")),
    rAUName_(dict.lookupOrDefault<word>("rAU", word::null)),
    implicit_(false),
    warnedExplicit_(false)
{
    if (Rp_ < 0 || C_ < 0 || Rd_ <= 0)
    {
        FatalIOErrorInFunction(dict)
            << "patch " << p.name() << ": need Rp >= 0, C >= 0, Rd > 0; got Rp "
            << Rp_ << ", C " << C_ << ", Rd " << Rd_ << exit(FatalIOError);
    }
    if (dict.found("value"))
    {
        fvPatchScalarField::operator=(scalarField("value", dict, p.size()));
    }
    else
    {
        fvPatchScalarField::operator=(Pc_);
    }
    refValue() = *this;
    refGrad() = Zero;
    valueFraction() = 1.0;
}


Foam::vcsWindkesselPressureFvPatchScalarField::
vcsWindkesselPressureFvPatchScalarField
(
    const vcsWindkesselPressureFvPatchScalarField& ptf,
    const fvPatch& p,
    const DimensionedField<scalar, volMesh>& iF,
    const fvPatchFieldMapper& mapper
)
:
    mixedFvPatchScalarField(ptf, p, iF, mapper),
    Rp_(ptf.Rp_),
    C_(ptf.C_),
    Rd_(ptf.Rd_),
    Pd_(ptf.Pd_),
    Pc_(ptf.Pc_),
    tState_(ptf.tState_),
    timeIndex_(ptf.timeIndex_),
    phiName_(ptf.phiName_),
    rAUName_(ptf.rAUName_),
    implicit_(ptf.implicit_),
    warnedExplicit_(ptf.warnedExplicit_)
{}


#ifdef OPENFOAM
Foam::vcsWindkesselPressureFvPatchScalarField::
vcsWindkesselPressureFvPatchScalarField
(
    const vcsWindkesselPressureFvPatchScalarField& ptf
)
:
    mixedFvPatchScalarField(ptf),
    Rp_(ptf.Rp_),
    C_(ptf.C_),
    Rd_(ptf.Rd_),
    Pd_(ptf.Pd_),
    Pc_(ptf.Pc_),
    tState_(ptf.tState_),
    timeIndex_(ptf.timeIndex_),
    phiName_(ptf.phiName_),
    rAUName_(ptf.rAUName_),
    implicit_(ptf.implicit_),
    warnedExplicit_(ptf.warnedExplicit_)
{}
#endif


Foam::vcsWindkesselPressureFvPatchScalarField::
vcsWindkesselPressureFvPatchScalarField
(
    const vcsWindkesselPressureFvPatchScalarField& ptf,
    const DimensionedField<scalar, volMesh>& iF
)
:
    mixedFvPatchScalarField(ptf, iF),
    Rp_(ptf.Rp_),
    C_(ptf.C_),
    Rd_(ptf.Rd_),
    Pd_(ptf.Pd_),
    Pc_(ptf.Pc_),
    tState_(ptf.tState_),
    timeIndex_(ptf.timeIndex_),
    phiName_(ptf.phiName_),
    rAUName_(ptf.rAUName_),
    implicit_(ptf.implicit_),
    warnedExplicit_(ptf.warnedExplicit_)
{}


// * * * * * * * * * * * * * * * Member Functions  * * * * * * * * * * * * * //

void Foam::vcsWindkesselPressureFvPatchScalarField::stepCoeffs
(
    const scalar h,
    scalar& Z,
    scalar& P0
) const
{
    const scalar tau = Rd_*C_;
    Z = Rp_ + Rd_*h/(tau + h);
    P0 = (tau*Pc_ + h*Pd_)/(tau + h);
}


void Foam::vcsWindkesselPressureFvPatchScalarField::updateCoeffs()
{
    if (updated())
    {
        return;
    }

    const Time& time = this->db().time();
    const label patchi = this->patch().index();
    const surfaceScalarField& phi =
        this->db().lookupObject<surfaceScalarField>(phiName_);

    // A new time step: advance the capacitor to the old time with the
    // converged flux of the previous step (phi still holds it)
    if (time.timeIndex() != timeIndex_)
    {
        timeIndex_ = time.timeIndex();
        const scalar tOld = time.value() - time.deltaTValue();
        const scalar h = tOld - tState_;
        if (h > 1e-9*time.deltaTValue())
        {
            const scalar Q = gSum(phi.boundaryField()[patchi]);
            const scalar tau = Rd_*C_;
            Pc_ = (tau*Pc_ + h*(Rd_*Q + Pd_))/(tau + h);
            tState_ = tOld;
        }
    }

    scalar Z = 0, P0 = 0;
    stepCoeffs(time.value() - tState_, Z, P0);

    // the pressure equation's diffusivity: SIMPLEC's/consistent PIMPLE's
    // rAtU = 1/(1/rAU - H1) when the solver made one, else rAU = 1/A
    word rAUName = rAUName_;
    if (rAUName.empty())
    {
        rAUName = "(1|((1|(1|A(U)))-H(1)))";
        if (!this->db().foundObject<volScalarField>(rAUName))
        {
            rAUName = "(1|A(U))";
        }
    }

    if
    (
        this->db().foundObject<surfaceScalarField>("phiHbyA")
     && this->db().foundObject<volScalarField>(rAUName)
    )
    {
        const surfaceScalarField& phiHbyA =
            this->db().lookupObject<surfaceScalarField>("phiHbyA");
        const volScalarField& rAU =
            this->db().lookupObject<volScalarField>(rAUName);

        // g_f = rAU_f |S_f| deltaCoeff_f: the pressure equation's boundary
        // conductance (gaussLaplacianScheme with a mixed condition)
        const scalarField g
        (
            rAU.boundaryField()[patchi]*this->patch().magSf()
           *this->patch().deltaCoeffs()
        );
        const scalar G = gSum(g);
        const scalar QH = gSum(phiHbyA.boundaryField()[patchi]);

        valueFraction() = 1.0/(1.0 + Z*G);
        refValue() = P0 + Z*QH;
        implicit_ = true;
    }
    else if (!implicit_)
    {
        if (!warnedExplicit_)
        {
            WarningInFunction
                << "patch " << this->patch().name() << ": no phiHbyA/"
                << rAUName << " registered (not in a pressure solve of "
                << "simpleFoam/pimpleFoam?): the Windkessel is coupled "
                << "explicitly (p = Z Q + P_0 from the last flux), which is "
                << "unstable with several outlets" << endl;
            warnedExplicit_ = true;
        }
        if (debug)
        {
            Info<< "vcsWindkesselPressure " << this->patch().name()
                << ": registered objects " << this->db().sortedToc() << endl;
        }
        // not within a pressure solve: explicit, from the current flux
        const scalar Q = gSum(phi.boundaryField()[patchi]);
        valueFraction() = 1.0;
        refValue() = P0 + Z*Q;
    }
    refGrad() = Zero;

    mixedFvPatchScalarField::updateCoeffs();
}


#ifdef OPENFOAM
    #define VCS_WRITE(key, value) os.writeEntry(key, value)
#else
    #define VCS_WRITE(key, value) writeEntry(os, key, value)
#endif

void Foam::vcsWindkesselPressureFvPatchScalarField::write(Ostream& os) const
{
    fvPatchScalarField::write(os);
    VCS_WRITE("Rp", Rp_);
    VCS_WRITE("C", C_);
    VCS_WRITE("Rd", Rd_);
    VCS_WRITE("Pd", Pd_);
    VCS_WRITE("Pc", Pc_);
    VCS_WRITE("tState", tState_);
    VCS_WRITE("phi", phiName_);
    if (!rAUName_.empty())
    {
        VCS_WRITE("rAU", rAUName_);
    }
#ifdef OPENFOAM
    this->writeEntry("value", os);
#else
    writeEntry(os, "value", *this);
#endif
}

#undef VCS_WRITE


// * * * * * * * * * * * * * * Build Macro Function  * * * * * * * * * * * * //

namespace Foam
{
    makePatchTypeField
    (
        fvPatchScalarField,
        vcsWindkesselPressureFvPatchScalarField
    );
}
